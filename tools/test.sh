#!/usr/bin/env bash
# Runs every test of the workspace, after installing the Python peers the tests compare against
# (Pinocchio for the dynamics, Cyclone DDS, the MCAP readers) into the project's virtual environment
# .venv (a stock Debian or Ubuntu Python refuses a global pip install, PEP 668) and the Debian packages
# the Fast DDS and Cyclone DDS peers of tests/interop.rs are built from (tools/dds-peers.sh).
# Usage: tools/test.sh [extra cargo test arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/python-env.sh
source tools/dds-peers.sh
# With DDS-Security compiled in (it stays off unless ROS_SECURITY_* asks for it): the secure graph's tests
# run too, and every other test shows that nothing changes without it. The `testing` profile is the
# release profile without its link-time optimisation (Cargo.toml).
cargo test --workspace --profile testing --features softcontact/security "$@"
