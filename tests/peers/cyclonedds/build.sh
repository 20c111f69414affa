#!/usr/bin/env bash
# Builds the Cyclone DDS peers (peer.c, and secure_peer.c for tests/security_interop.rs) into
# target/peers/cyclonedds/cyclonedds_peer and cyclonedds_secure_peer: idlc generates the
# types of ros2_types.idl, cc links them with Debian's Cyclone DDS 0.10 (cyclonedds-dev,
# cyclonedds-tools). Without those packages it says which to install and exits 1.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$here/../../../target/peers/cyclonedds"
for need in idlc cc; do
  command -v "$need" >/dev/null || { echo "cyclonedds peer: $need missing (apt-get install cyclonedds-dev cyclonedds-tools gcc)" >&2; exit 1; }
done
[ -e /usr/include/dds/dds.h ] || { echo "cyclonedds peer: headers missing (apt-get install cyclonedds-dev)" >&2; exit 1; }
mkdir -p "$out/gen"
fresh() { [ "$out/$1" -nt "$here/$2" ] && [ "$out/$1" -nt "$here/ros2_types.idl" ]; }
if fresh cyclonedds_peer peer.c && fresh cyclonedds_secure_peer secure_peer.c; then
  exit 0
fi
(cd "$out/gen" && idlc "$here/ros2_types.idl" 2>/dev/null)
cc -std=c11 -D_POSIX_C_SOURCE=200809L -O1 -Wall -I"$out/gen" -o "$out/cyclonedds_peer" "$here/peer.c" \
  "$out/gen/ros2_types.c" -lddsc
cc -std=c11 -D_POSIX_C_SOURCE=200809L -O1 -Wall -I"$out/gen" -o "$out/cyclonedds_secure_peer" "$here/secure_peer.c" \
  "$out/gen/ros2_types.c" -lddsc
