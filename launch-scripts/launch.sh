#!/usr/bin/env bash
# The node graph, started, watched and stopped as one: the implementation behind sim.sh and robot.sh.
#
#   launch.sh --sim|--robot [--isolated] [--lockstep] [--separate] [--secure] [--surface sponge|dice|lab_sponge|lab_dice|none]
#             [--log-dir DIR] [--params-file FILE]... [--nodes N1,N2...] [--run COMMAND [ARGS...]]
#
# Starts the nodes with the parameter files of config/ (plus any --params-file overlays, later ones win),
# waits until every node has said it is ready, then either runs COMMAND (and stops the graph when it
# returns, exiting with its status) or waits for Ctrl-C. When any node dies, the others are stopped too.
# Stopping is SIGTERM to each node in turn (controller first, so the driver holds the arm), SIGKILL after
# 5 s. The exit status is non-zero if a node failed or was killed, or COMMAND failed. Each node's log
# (its exit report included) is in the log folder.
#
# The 1 kHz path runs composed by default: lwr_driver, ft_sensor and deformation_controller as components of one
# process, lwr_control (the controller answers each FRI measurement on the driver's thread); the contact
# estimator is a process of its own. --separate runs each of the three as its own process instead.
#
# --nodes starts only the nodes named (e.g. --nodes contact_estimator to replay a recording into it).
# --isolated runs everything in a new network namespace with only loopback (DDS never leaves the machine;
# needs unprivileged user namespaces). Binaries: $SOFTCONTACT_BIN (default target/release, built with
# `cargo build --release` when missing).
#
# --secure runs the graph with ROS 2 security (DDS-Security: authenticated, encrypted, each process held to
# its enclave's permissions; docs/safety.md): the keystore of $ROS_SECURITY_KEYSTORE, or a new one in the
# log folder (`softcontact security create-keystore DIR --enclaves`), ROS_SECURITY_ENABLE=true and
# ROS_SECURITY_STRATEGY=Enforce, each process in the enclave of its name, and COMMAND in /user's
# (ROS_SECURITY_ENCLAVE_OVERRIDE). The binaries must be built with `--features softcontact/security`.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(dirname "$here")"
mode="" isolated=0 lockstep=0 separate=0 secure=0 surface="" log_dir="" only="" run=() overlays=()
while (($#)); do
    case "$1" in
    --sim) mode=sim ;;
    --robot) mode=robot ;;
    --isolated) isolated=1 ;;
    --lockstep) lockstep=1 ;;
    --separate) separate=1 ;;
    --secure) secure=1 ;;
    --surface) surface="$2"; shift ;;
    --log-dir) log_dir="$2"; shift ;;
    --params-file) overlays+=("$(realpath "$2")"); shift ;;
    --nodes) only="$2"; shift ;;
    --run) shift; run=("$@"); break ;;
    -h | --help) sed -n '2,/^[^#]/p' "${BASH_SOURCE[0]}" | grep '^#' | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "launch: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
    shift
done
[[ -n "$mode" ]] || { echo "launch: --sim or --robot" >&2; exit 2; }

if ((isolated)) && [[ -z "${SOFTCONTACT_NETNS:-}" ]]; then
    command -v unshare >/dev/null || { echo "launch: --isolated needs unshare (util-linux)" >&2; exit 2; }
    command -v ip >/dev/null || { echo "launch: --isolated needs ip (iproute2)" >&2; exit 2; }
    args=("--$mode" --isolated)
    ((lockstep)) && args+=(--lockstep)
    ((separate)) && args+=(--separate)
    ((secure)) && args+=(--secure)
    [[ -n "$surface" ]] && args+=(--surface "$surface")
    [[ -n "$log_dir" ]] && args+=(--log-dir "$(realpath -m "$log_dir")")
    for o in "${overlays[@]}"; do args+=(--params-file "$o"); done
    [[ -n "$only" ]] && args+=(--nodes "$only")
    ((${#run[@]})) && args+=(--run "${run[@]}")
    # -f: the namespace's first process is this script's copy, so Ctrl-C reaches it as before.
    exec unshare --map-root-user --net env SOFTCONTACT_NETNS=1 bash "${BASH_SOURCE[0]}" "${args[@]}"
fi
if [[ -n "${SOFTCONTACT_NETNS:-}" ]]; then
    ip link set lo up
    ip link set lo multicast on
    ip route add 224.0.0.0/4 dev lo
fi

bin="${SOFTCONTACT_BIN:-$root/target/release}"
if ((separate)); then
    nodes=(lwr_driver ft_sensor contact_estimator deformation_controller)
else
    nodes=(lwr_control contact_estimator)
fi
[[ "$mode" == sim ]] && nodes=(sim_arm "${nodes[@]}")
if [[ -n "$only" ]]; then
    for n in ${only//,/ }; do
        [[ " ${nodes[*]} " == *" $n "* ]] || { echo "launch: no node $n (nodes: ${nodes[*]})" >&2; exit 2; }
    done
    IFS=, read -r -a nodes <<<"$only"
fi
for n in "${nodes[@]}"; do
    if [[ ! -x "$bin/$n" ]]; then
        [[ -z "${SOFTCONTACT_BIN:-}" ]] || { echo "launch: $bin/$n missing" >&2; exit 2; }
        echo "launch: building the nodes (cargo build --release)…" >&2
        features=()
        ((secure)) && features=(--features softcontact/security)
        (cd "$root" && cargo build --release -q -p softcontact -p softcontact-nodes -p softcontact-simcell --bins "${features[@]}")
        break
    fi
done

log_dir="${log_dir:-$(mktemp -d -t softcontact-graph.XXXXXX)}"
mkdir -p "$log_dir"
echo "launch: logs in $log_dir" >&2

if ((secure)); then
    export ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce
    export ROS_SECURITY_KEYSTORE="${ROS_SECURITY_KEYSTORE:-$log_dir/keystore}"
    if [[ ! -f "$ROS_SECURITY_KEYSTORE/enclaves/governance.p7s" ]]; then
        "$bin/softcontact" security create-keystore "$ROS_SECURITY_KEYSTORE" --enclaves >"$log_dir/keystore.log" ||
            { echo "launch: no keystore in $ROS_SECURITY_KEYSTORE" >&2; cat "$log_dir/keystore.log" >&2; exit 1; }
    fi
    echo "launch: secure: keystore $ROS_SECURITY_KEYSTORE, Enforce" >&2
fi

# The parameters of one node: its file, the robot overlay, the user's overlays, then the mode's settings.
params_of() {
    local n="$1" p=() f
    if [[ "$n" == lwr_control ]]; then
        for f in lwr_driver ft_sensor deformation_controller; do p+=(--params-file "$root/config/$f.yaml"); done
    else
        p+=(--params-file "$root/config/$n.yaml")
    fi
    [[ "$mode" == robot ]] && p+=(--params-file "$root/config/robot.yaml")
    for o in "${overlays[@]}"; do p+=(--params-file "$o"); done
    if ((lockstep)); then
        if [[ "$n" == sim_arm ]]; then p+=(-p lockstep:=true); else p+=(-p use_sim_time:=true); fi
    fi
    [[ "$n" == sim_arm && -n "$surface" ]] && p+=(-p "surface:=$surface")
    ((secure)) && p+=(--enclave "/$n")
    printf '%s\n' "${p[@]}"
}

declare -A pid_of=()
stopping=0
stop_all() {
    ((stopping)) && return
    stopping=1
    local order=(deformation_controller contact_estimator ft_sensor lwr_driver lwr_control sim_arm) n
    for n in "${order[@]}"; do
        [[ -n "${pid_of[$n]:-}" ]] || continue
        kill -TERM "${pid_of[$n]}" 2>/dev/null || continue
        for _ in $(seq 50); do kill -0 "${pid_of[$n]}" 2>/dev/null || break; sleep 0.1; done
        kill -KILL "${pid_of[$n]}" 2>/dev/null && echo "launch: $n did not stop in 5 s: killed" >&2 || true
    done
}
trap 'echo "launch: stopping" >&2; stop_all' INT TERM

# The FRI path first: the driver (and the cell it answers) keep the normal priority, the controller and
# the sensor a little less, the estimator's refits least (unprivileged users may lower priority only; on
# the robot give the driver a real-time priority, see launch-scripts/README.md).
# Each process of the 1 kHz path runs in a session of its own: Linux's autogroup scheduling (on by
# default in Debian's and Ubuntu's kernels) shares the CPU between sessions before threads, so busy work
# elsewhere at the same nice value cannot keep the FRI thread waiting for a scheduler tick when a
# datagram arrives (tools/bench-graph.sh, a busy loop per core: 99.7 % of replies within 200 us in one
# session with them, 99.98 % in sessions of their own). The script still stops them (stop_all). Not in
# lockstep, where the simulated time waits for the driver's answer but not for the F/T node: there the
# sessions' shares let the sensor's thread fall behind the simulation (stale forces in 2 runs of 5).
declare -A nice_of=([sim_arm]=0 [lwr_control]=0 [lwr_driver]=0 [deformation_controller]=2 [ft_sensor]=2 [contact_estimator]=10)
for n in "${nodes[@]}"; do
    mapfile -t p < <(params_of "$n")
    session=(setsid)
    if [[ $n == contact_estimator ]] || ((lockstep)); then session=(); fi
    "${session[@]}" nice -n "${nice_of[$n]}" "$bin/$n" "${p[@]}" </dev/null >"$log_dir/$n.log" 2>&1 &
    pid_of[$n]=$!
done

# Ready when every node has said so; a node that dies first fails the launch.
deadline=$((SECONDS + 30))
for n in "${nodes[@]}"; do
    until grep -q "ready" "$log_dir/$n.log" 2>/dev/null; do
        if ! kill -0 "${pid_of[$n]}" 2>/dev/null || ((SECONDS > deadline)); then
            echo "launch: $n did not come up; its log:" >&2
            sed 's/^/    /' "$log_dir/$n.log" >&2
            stop_all
            exit 1
        fi
        sleep 0.05
    done
done
echo "launch: up: ${nodes[*]}" >&2

status=0
if ((${#run[@]})); then
    # The command runs in the background so that Ctrl-C (trapped above) still stops the graph at once.
    if ((secure)); then ROS_SECURITY_ENCLAVE_OVERRIDE=/user "${run[@]}" & else "${run[@]}" & fi
    run_pid=$!
    while kill -0 "$run_pid" 2>/dev/null; do
        wait -n || true
        ((stopping)) && break
        for n in "${nodes[@]}"; do
            kill -0 "${pid_of[$n]}" 2>/dev/null || { echo "launch: $n exited while the command ran" >&2; status=1; break 2; }
        done
    done
    if ((stopping || status)); then kill -TERM "$run_pid" 2>/dev/null || true; fi
    wait "$run_pid" || status=$?
else
    wait -n || true
    ((stopping)) || echo "launch: a node exited; stopping the others" >&2
fi
stop_all

for n in "${nodes[@]}"; do
    code=0
    wait "${pid_of[$n]}" || code=$?
    if ((code != 0)); then
        echo "launch: $n exited with status $code; its log ends:" >&2
        tail -n 15 "$log_dir/$n.log" | sed 's/^/    /' >&2
        status=1
    fi
    grep -h -E "exit|latency|send call|command age|RSS" "$log_dir/$n.log" | sed 's/^/  /' >&2 || true
done
exit "$status"
