#!/usr/bin/env bash
# Runs every test of the workspace, after installing the Python peers the tests compare against
# (Pinocchio for the dynamics, Cyclone DDS, the MCAP readers) into the project's virtual environment
# .venv (a stock Debian or Ubuntu Python refuses a global pip install, PEP 668).
# Usage: tools/test.sh [extra cargo test arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/python-env.sh
cargo test --workspace --release "$@"
