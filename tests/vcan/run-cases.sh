#!/usr/bin/env bash
# Runs every case of tests/vcan/cases and leaves per case, in RESULTS:
#   NAME.json (what probebridge wrote with --json), NAME.exit (its exit status),
#   NAME.stdout / NAME.stderr, NAME.sim.log (the simulator process, with IFACE).
#
# Usage: run-cases.sh RESULTS [IFACE]
#   without IFACE: on the host, built-in simulator on the in-process bus (the reference);
#   with IFACE:    `probebridge sim` on IFACE in its own process, the bridge on IFACE;
#                  before each case a marker frame 7FF#<case number> goes on the bus so
#                  the candump log can be split per case (0x7FF is in CiA 301's
#                  restricted range: no CANopen device uses it).
# PROBEBRIDGE_BIN: the probebridge binary (default target/release/probebridge).
# PROBEBRIDGE_VCAN_CONFIGS: a folder holding configs/scenarios and configs/machines to
#   use instead of the repository's (.ci/vcan/run writes one with the bus timing
#   relaxed for the emulated VM); programs always come from the repository.
# The machine's state of `run` and `check` is RESULTS/NAME.state (`--state-dir`;
# again=OTHER in EXPECT: OTHER's, left by that case), never the tree.
# The files a program writes (`--presets FILE`, `--kinematics FILE` in ARGS: the preset
# table, the active kinematics) are copied first to RESULTS/NAME.state/ (FILE relative
# to PROBEBRIDGE_VCAN_CONFIGS; a FILE that does not exist there starts absent), and the
# case works on the copy: the VM sees the repository read-only, and the shipped files
# stay as they are.
set -u
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
RESULTS=$1
IFACE=${2:-}
BIN=${PROBEBRIDGE_BIN:-$ROOT/target/release/probebridge}
CONFIGS=${PROBEBRIDGE_VCAN_CONFIGS:-$ROOT}
CASE_TIMEOUT=${PROBEBRIDGE_CASE_TIMEOUT:-420}
mkdir -p "$RESULTS"
cd "$ROOT"

trim() { local s=$1; s=${s#"${s%%[![:space:]]*}"}; s=${s%"${s##*[![:space:]]}"}; printf '%s' "$s"; }

n=0
while IFS='|' read -r name scenario args expect; do
    name=$(trim "$name")
    case "$name" in ''|'#'*) continue ;; esac
    n=$((n + 1))
    scenario=$CONFIGS/$(trim "$scenario")
    args=$(trim "$args")
    # shellcheck disable=SC2206 # the arguments are words without spaces
    argv=($args)
    extra=(--scenario "$scenario")
    moves=
    case "${argv[0]}" in
        probe) moves=1; extra+=(--json "$RESULTS/$name.json" --service "pbvcan-$name") ;;
        run) moves=1; extra+=(--json "$RESULTS/$name.json" --service "pbvcan-$name" --out "$RESULTS/$name.protocols") ;;
        check) ;; # validation only: no bus, no JSON
        *) echo "tests/vcan/cases: $name: unknown command ${argv[0]}" >&2 ;;
    esac
    # on=host: the host reference runs it; the VM does not (tests/vcan/cases says why).
    if [ -n "$IFACE" ] && printf '%s\n' $expect | grep -qx 'on=host'; then
        echo "== case $n $name: on the host only (on=host)"
        continue
    fi
    rm -rf "$RESULTS/$name".*
    # The machine's state: the case's own folder, or with again=NAME that of case NAME
    # (which ran before it), so the example runs a second time on what the first left.
    again=$(printf '%s\n' $expect | sed -n 's/^again=//p')
    state="$RESULTS/${again:-$name}.state"
    case "${argv[0]}" in
        run|check) extra+=(--state-dir "$state") ;;
    esac
    for ((i = 0; i + 1 < ${#argv[@]}; i++)); do
        case "${argv[$i]}" in
            --presets|--kinematics)
                src=${argv[$((i + 1))]}
                dst="$RESULTS/$name.state/$(basename "$src")"
                mkdir -p "$RESULTS/$name.state"
                if [ -f "$CONFIGS/$src" ]; then cp "$CONFIGS/$src" "$dst"; fi
                argv[i+1]=$dst
                ;;
        esac
    done
    sim_pid=
    # On the bus, the drives (`sim`) and the master share one CPU, the last: in the
    # emulated VM of a loaded host, one vCPU can stall for 200 ms while the other runs.
    # With the master on the running one, it went on sending SYNCs the stalled drives
    # answered later in a burst, moving for each before their latch could reach it
    # (in CI, past the probe's 5 mm overtravel: EMCY 0xFF01). Hardware drives do not
    # stall; on one CPU the two stall together, and the master never runs ahead of
    # drives that stand still.
    pin=()
    if [ -n "$IFACE" ]; then
        pin=(taskset -c "$(($(nproc) - 1))")
    fi
    if [ -n "$IFACE" ]; then
        cansend "$IFACE" "7FF#$(printf '%02X' "$n")"
    fi
    if [ -n "$IFACE" ] && [ -n "$moves" ]; then
        extra+=(--can "$IFACE")
        "${pin[@]}" "$BIN" sim --scenario "$scenario" --can "$IFACE" > "$RESULTS/$name.sim.log" 2>&1 &
        sim_pid=$!
        # The simulator prints its banner once its socket is open: the bridge's NMT
        # reset must not go out before that.
        for _ in $(seq 100); do
            grep -q 'probebridge sim:' "$RESULTS/$name.sim.log" 2>/dev/null && break
            sleep 0.1
        done
    fi
    echo "== case $n $name: probebridge ${argv[*]} ${extra[*]}"
    start=$(date +%s)
    timeout "$CASE_TIMEOUT" "${pin[@]}" "$BIN" "${argv[@]}" "${extra[@]}" \
        > "$RESULTS/$name.stdout" 2> "$RESULTS/$name.stderr" < /dev/null
    status=$?
    echo "$status" > "$RESULTS/$name.exit"
    echo "   exit $status after $(( $(date +%s) - start )) s"
    if [ -n "$sim_pid" ]; then
        kill "$sim_pid" 2>/dev/null
        wait "$sim_pid" 2>/dev/null
    fi
done < "$ROOT/tests/vcan/cases"
echo "$n" > "$RESULTS/cases.count"
