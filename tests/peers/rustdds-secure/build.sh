#!/usr/bin/env bash
# Builds the secure RustDDS peer (src/main.rs, on vendor/rustdds with its `security` feature) into
# target/peers/rustdds-secure/release/rustdds-secure-peer, in its own workspace and target folder.
# openssl-sys needs pkg-config and the OpenSSL headers (apt-get install pkg-config libssl-dev).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
export CARGO_TARGET_DIR="$here/../../../target/peers/rustdds-secure"
exec cargo build --release --locked --quiet --manifest-path "$here/Cargo.toml"
