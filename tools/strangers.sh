#!/usr/bin/env bash
# Strangers on a secure graph's domain: N Cyclone DDS 0.10 peers without credentials and N enrolled by
# another authority, idle at nice 19 for SECONDS, for the denial-of-service measurement of
# docs/safety.md. Run it as the command of a secure graph, which stays in its loopback-only namespace:
#
#   cargo build --release --features softcontact/security && tests/peers/cyclonedds/build.sh
#   launch-scripts/sim.sh --isolated --secure --log-dir out/strangers --run tools/strangers.sh 20 25
#
# then read the graph's exit reports in out/strangers (KRC sessions, the FRI answer's latency, the
# participants refused). With STRANGERS_CGROUP set to a cgroup v1 CPU folder made beforehand outside
# the namespace, e.g. `mkdir /sys/fs/cgroup/cpu/strangers && echo 30000 >
# /sys/fs/cgroup/cpu/strangers/cpu.cfs_quota_us` (30 % of a core), the strangers run in it, as if on
# another machine with only their traffic reaching this one.
# Usage: tools/strangers.sh [N (20)] [SECONDS (25)]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
n="${1:-20}" seconds="${2:-25}"
bin="${SOFTCONTACT_BIN:-$root/target/release}"
peer="$root/target/peers/cyclonedds/cyclonedds_peer"
[[ -x $peer ]] || { echo "strangers: no $peer (tests/peers/cyclonedds/build.sh)" >&2; exit 2; }
auth="$(find /usr/lib -name libdds_security_auth.so -print -quit)"
[[ -n $auth ]] || { echo "strangers: Cyclone DDS's security plugins missing (apt-get install cyclonedds-dev)" >&2; exit 2; }
plugins="$(dirname "$auth")"
work="$(mktemp -d -t softcontact-strangers.XXXXXX)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT
if [[ -n ${STRANGERS_CGROUP:-} ]]; then
    echo $$ > "$STRANGERS_CGROUP/tasks"
fi
"$bin/softcontact" security create-keystore "$work/other_ca" --enclaves > /dev/null
e="$work/other_ca/enclaves/user"
lo='<General><Interfaces><NetworkInterface name="lo" multicast="true"/></Interfaces></General>'
lib() { echo "<Library path=\"$plugins/libdds_security_$1.so\" initFunction=\"init_$2\" finalizeFunction=\"finalize_$2\"/>"; }
security="<Security><Authentication>$(lib auth authentication)<IdentityCA>file:$e/identity_ca.cert.pem</IdentityCA>\
<IdentityCertificate>file:$e/cert.pem</IdentityCertificate><PrivateKey>file:$e/key.pem</PrivateKey></Authentication>\
<AccessControl>$(lib ac access_control)<PermissionsCA>file:$e/permissions_ca.cert.pem</PermissionsCA>\
<Governance>file:$e/governance.p7s</Governance><Permissions>file:$e/permissions.p7s</Permissions></AccessControl>\
<Cryptographic>$(lib crypto crypto)</Cryptographic></Security>"
for i in $(seq "$n"); do
    CYCLONEDDS_URI="<CycloneDDS><Domain id=\"any\">$lo</Domain></CycloneDDS>" \
        nice -n 19 "$peer" 1 1 "$seconds" > /dev/null 2>&1 &
    CYCLONEDDS_URI="<CycloneDDS><Domain id=\"any\">$lo$security</Domain></CycloneDDS>" \
        nice -n 19 "$peer" 1 1 "$seconds" > /dev/null 2>&1 &
done
echo "strangers: $n without credentials and $n of another authority for $seconds s"
sleep "$seconds"
