# Sourced by tools/test.sh: the Debian packages the other vendors' DDS peers of tests/interop.rs are built
# from — Fast DDS 2.9 with fastddsgen, Cyclone DDS 0.10 with idlc, a C/C++ compiler — and what the
# DDS-Security peers of tests/security_interop.rs need (pkg-config and the OpenSSL headers for RustDDS's
# `security` feature, the openssl command for the keystore) — installed when
# missing: as root with apt-get; otherwise it stops and prints the command to run.
peer_packages="libfastrtps-dev fastddsgen cyclonedds-dev cyclonedds-tools g++ pkg-config libssl-dev openssl"
missing=""
for p in $peer_packages; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "dds-peers: installing$missing with apt-get"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing >/dev/null
  else
    echo "dds-peers: the interop peers need$missing; run: sudo apt-get install$missing" >&2
    exit 1
  fi
fi
