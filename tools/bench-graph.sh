#!/usr/bin/env bash
# The 1 kHz path under load, the graph as launch-scripts/sim.sh runs it: a busy loop on each core at the
# nodes' priority, everything in a loopback-only network namespace, force commands running (60 N and 30 N
# in turn) for SECONDS (default 60). Prints the driver's exit report: reply latency timed from the kernel's
# receive timestamp of each FRI datagram, the age of the joint state behind each applied command, and the
# cycles answered with a held command (stale cycles; those after the first command exclude start-up).
#
#   tools/bench-graph.sh [--separate] [--seconds N] [--log-dir DIR]
#
# --separate: driver, F/T node and controller as three processes (commands cross DDS); default: composed.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=60 layout=() log_dir=""
while (($#)); do
    case "$1" in
    --separate) layout=(--separate) ;;
    --seconds) seconds="$2"; shift ;;
    --log-dir) log_dir="$2"; shift ;;
    -h | --help) sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench-graph: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
    shift
done
((seconds >= 15)) || { echo "bench-graph: --seconds at least 15 (8 s of start-up and approach first)" >&2; exit 2; }
cargo build --release -q -p softcontact-nodes -p softcontact-simcell --bins
cargo build --release -q --bin softcontact
log_dir="${log_dir:-$(mktemp -d -t softcontact-bench-graph.XXXXXX)}"

busy=()
for _ in $(seq "$(nproc)"); do
    (while :; do :; done) &
    busy+=($!)
done
trap 'kill "${busy[@]}" 2>/dev/null || true' EXIT

echo "bench-graph: $(nproc) busy loops, ${layout[*]:-composed} layout, $seconds s; logs in $log_dir" >&2
launch-scripts/sim.sh --isolated "${layout[@]}" --log-dir "$log_dir" --run bash -c "
    sleep 8
    end=\$((SECONDS + $seconds - 8))
    while ((SECONDS < end)); do
        target/release/softcontact force 60 >/dev/null || true
        target/release/softcontact force 30 >/dev/null || true
    done" 2>/dev/null || { echo "bench-graph: the graph failed; logs in $log_dir" >&2; exit 1; }
grep -h -E "^lwr_driver: (exit|reply latency|command age|commands applied)|^deformation_controller: exit" "$log_dir"/*.log
