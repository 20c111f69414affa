#!/usr/bin/env bash
# Builds (once, cached under target/) and runs Pinocchio's C++ timing program against the `pin` wheel's
# own headers and libraries. Needs: pip install pin cmeel-eigen cmeel-urdfdom-headers.
# Usage: run.sh URDF [CALLS] [REPS]   -> prints one JSON object of ns per call.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../../.." && pwd)
py=${SOFTCONTACT_PYTHON:-python3}
P=$("$py" -c 'import sysconfig, os; print(os.path.join(sysconfig.get_paths()["purelib"], "cmeel.prefix"))')
[ -d "$P/include/pinocchio" ] || { echo "run.sh: Pinocchio headers not found under $P (pip install pin cmeel-eigen cmeel-urdfdom-headers)" >&2; exit 1; }
out="$root/target/pinocchio-bench"
mkdir -p "$out"
bin="$out/bench-$(sha256sum "$here/bench.cpp" | cut -c1-12)"
if [ ! -x "$bin" ]; then
  echo "run.sh: compiling Pinocchio benchmark (2-4 min, once)" >&2
  # Defines from the wheel's lib/cmake/pinocchio/pinocchioTargets.cmake. No -march=native: the wheel's
  # libraries are generic x86-64 and an Eigen ABI mismatch segfaults.
  g++ -std=c++17 -O3 -DNDEBUG -DPINOCCHIO_WITH_URDFDOM \
    -DPINOCCHIO_URDFDOM_HEADERS_MAJOR_VERSION=3 -DPINOCCHIO_URDFDOM_HEADERS_MINOR_VERSION=0 \
    -DPINOCCHIO_URDFDOM_HEADERS_PATCH_VERSION=0 -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
    -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_FUSION_INVOKE_MAX_ARITY=12 \
    -I"$P/include" -I"$P/include/eigen3" -I"$P/include/urdfdom" -I"$P/include/urdfdom_headers" \
    "$here/bench.cpp" -o "$bin.tmp" -L"$P/lib" -Wl,-rpath,"$P/lib" \
    -lpinocchio_parsers -lpinocchio_default -lurdfdom_model -lboost_filesystem -lboost_serialization
  mv "$bin.tmp" "$bin"
fi
exec "$bin" "$@"
