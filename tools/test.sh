#!/usr/bin/env bash
# Runs every test of the workspace, after installing the Python peers the tests compare against
# (Pinocchio for the dynamics, Cyclone DDS, the MCAP readers). Usage: tools/test.sh [extra cargo test arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
python=${SOFTCONTACT_PYTHON:-python3}
"$python" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore -r requirements-test.txt
cargo test --workspace --release "$@"
