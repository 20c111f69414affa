#!/usr/bin/env bash
# Builds the Fast DDS peer (peer.cpp) into target/peers/fastdds/fastdds_peer: fastddsgen generates the
# types of ros2_types.idl, g++ links them with Debian's Fast DDS 2.9 (libfastrtps-dev). Without those
# packages it says which to install and exits 1.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$here/../../../target/peers/fastdds"
for need in fastddsgen g++; do
  command -v "$need" >/dev/null || { echo "fastdds peer: $need missing (apt-get install libfastrtps-dev fastddsgen g++)" >&2; exit 1; }
done
[ -e /usr/include/fastdds/dds/domain/DomainParticipant.hpp ] \
  || { echo "fastdds peer: Fast DDS headers missing (apt-get install libfastrtps-dev)" >&2; exit 1; }
mkdir -p "$out/gen"
if [ "$out/fastdds_peer" -nt "$here/peer.cpp" ] && [ "$out/fastdds_peer" -nt "$here/ros2_types.idl" ]; then
  exit 0
fi
fastddsgen -replace -d "$out/gen" "$here/ros2_types.idl" >/dev/null
g++ -std=c++17 -O1 -I"$out/gen" -o "$out/fastdds_peer" "$here/peer.cpp" \
  "$out/gen/ros2_types.cxx" "$out/gen/ros2_typesPubSubTypes.cxx" -lfastrtps -lfastcdr -lpthread
