#!/usr/bin/env bash
# Runs inside the throwaway VM that .ci/vcan/run boots (the host's filesystem is
# visible read-only, RESULTS is the writable --rwdir). Brings up vcan0, records all
# traffic with candump, runs the cases of tests/vcan/cases against `probebridge sim`
# on vcan0, a third-party master (python-canopen) against `probebridge sim`, our
# master's start-up against a device that is not ours (a python-canopen LocalNode),
# a killed master (SIGKILL) and a SIGTERM mid-451, then the Machine conformance suite
# on the SocketCAN backend. Everything it finds
# goes into RESULTS; the host checks it (vng does not return the exit status).
#
# Usage: in-vm.sh RESULTS PROBEBRIDGE_BIN CONFORMANCE_TEST_EXE FOREIGN_MASTER_BIN PYTHON
#   PYTHON: the python of the venv with canopen and python-can (.ci/vcan/setup).
set -u
RESULTS=$1
export PROBEBRIDGE_BIN=$2
CONFORMANCE=$3
FOREIGN_MASTER=$4
PYTHON=$5
# The name the foreign device gives itself (0x1008, segmented: longer than 4 bytes).
FOREIGN_NAME="python-canopen LocalNode CiA 402 drive"
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
export IOX2_LOG_LEVEL=${IOX2_LOG_LEVEL:-Error}
# The machine's state of a run without --state-dir (the signal runs below): writable,
# in the results, never the (read-only) tree or a home folder.
export XDG_STATE_HOME=$RESULTS/xdg-state
exec > "$RESULTS/vm.log" 2>&1
echo "vm: $(uname -r), $(nproc) cpus, $(awk '/MemTotal/ {print $2 " kB"}' /proc/meminfo)"
date +%s > "$RESULTS/vm.started"

# can-bcm: python-can's periodic sends (the LocalNode's heartbeat) use the kernel's
# broadcast manager.
modprobe can-bcm || echo "vm: no can-bcm module"
if ! { modprobe vcan && ip link add dev vcan0 type vcan && ip link set vcan0 up; }; then
    echo "vm: cannot bring up vcan0" | tee "$RESULTS/vm.error"
    exit 1
fi
ip -details link show vcan0
# Room for a few seconds of traffic in every socket's receive queue: the emulated CPUs
# stall now and then, and a full queue drops frames silently (candump's included).
sysctl -q -w net.core.rmem_default=8388608 net.core.rmem_max=8388608
echo "vm: conformance suite: SYNC period ${PROBEBRIDGE_TEST_CAN_SYNC_US:-of the machine} us," \
    "heartbeat timeout ${PROBEBRIDGE_TEST_CAN_HEARTBEAT_TIMEOUT_MS:-of the machine} ms," \
    "master heartbeat ${PROBEBRIDGE_TEST_CAN_MASTER_HEARTBEAT_MS:-of the machine} ms;" \
    "cases: configs from ${PROBEBRIDGE_VCAN_CONFIGS:-the repository}"

# The log grows by a few thousand frames a second: keep it in the VM's memory and
# copy it out at the end (the results folder is a synchronous 9p mount).
mkdir -p /run/pbvcan
candump -L vcan0 > /run/pbvcan/candump.log &
candump_pid=$!
sleep 0.5

bash "$ROOT/tests/vcan/run-cases.sh" "$RESULTS" vcan0

# A `probebridge run` of cycle 451 against `probebridge sim` on vcan0, stopped by
# SIGNAL once its first contact of cycle 451 is on stderr. Marker frames around it on
# the bus: 7FF#<START> before it starts, 7FF#<SENT> right after the signal went out,
# 7FF#<EXITED> once the process has exited (so the candump log says what happened
# before the exit). Leaves NAME.exit, NAME.stderr, NAME.json, NAME.sim.log; the
# simulator keeps running (its pid in sim_pid) for what the caller asks it next.
signal_mid_451() {
    local name=$1 signal=$2 start=$3 sent=$4 exited=$5
    local scenario=${PROBEBRIDGE_VCAN_CONFIGS:-$ROOT}/configs/scenarios/demo-sphere.toml
    cansend vcan0 "7FF#$start"
    "$PROBEBRIDGE_BIN" sim --scenario "$scenario" --can vcan0 > "$RESULTS/$name.sim.log" 2>&1 &
    sim_pid=$!
    for _ in $(seq 100); do
        grep -q 'probebridge sim:' "$RESULTS/$name.sim.log" 2>/dev/null && break
        sleep 0.1
    done
    "$PROBEBRIDGE_BIN" run "$ROOT/tests/vcan/programs/451-check-vcan.h" --yes --scenario "$scenario" \
        --can vcan0 --json "$RESULTS/$name.json" --out "$RESULTS/$name.protocols" \
        --service "pbvcan-$name" > "$RESULTS/$name.stdout" 2> "$RESULTS/$name.stderr" < /dev/null &
    local pid=$!
    local mid=
    for _ in $(seq 1200); do
        if awk '/cycle 451/ {c = 1} c && /contact at/ {found = 1; exit} END {exit !found}' \
            "$RESULTS/$name.stderr"; then
            mid=1
            break
        fi
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.1
    done
    [ -n "$mid" ] || echo "   $name: no contact of cycle 451 on stderr before the signal"
    kill "-$signal" "$pid"
    cansend vcan0 "7FF#$sent"
    date +%s.%N > "$RESULTS/$name.signalled"
    wait "$pid"
    echo $? > "$RESULTS/$name.exit"
    cansend vcan0 "7FF#$exited"
    date +%s.%N > "$RESULTS/$name.exited"
    echo "   $name: exit $(cat "$RESULTS/$name.exit")"
}

echo "== a killed master (SIGKILL mid-451): the drives notice its heartbeat is gone"
signal_mid_451 kill KILL FC FB FA
# The drives log the loss (EMCY 8130 on the bus); wait for every drive's line (the
# consumer time is a few seconds in the VM), then ask each its statusword over SDO:
# the five axes' drives and the spindle's (node 6).
for _ in $(seq 300); do
    [ "$(grep -c 'heartbeat of node .* lost' "$RESULTS/kill.sim.log")" -ge 6 ] && break
    sleep 0.1
done
sleep 0.5
for n in 1 2 3 4 5 6; do
    cansend vcan0 "60$n#4041600000000000"
    sleep 0.1
done
kill "$sim_pid"
wait "$sim_pid" 2>/dev/null
grep 'heartbeat of node' "$RESULTS/kill.sim.log" | sed 's/^/   /'

echo "== SIGTERM mid-451 over vcan: the drives are disabled before the process exits"
signal_mid_451 sigterm TERM F9 F8 F7
kill "$sim_pid"
wait "$sim_pid" 2>/dev/null

echo "== python-canopen: a third-party master against probebridge sim (drive-fault)"
cansend vcan0 7FF#FD
start=$(date +%s)
timeout 300 "$PYTHON" "$ROOT/tests/vcan/canopen_master.py" --iface vcan0 \
    --eds "$ROOT/tests/vcan/cia402-drive.eds" -- \
    "$PROBEBRIDGE_BIN" sim --scenario "$ROOT/configs/scenarios/drive-fault.toml" --can vcan0 \
    > "$RESULTS/python-canopen.log" 2>&1
echo $? > "$RESULTS/python-canopen.exit"
echo "   exit $(cat "$RESULTS/python-canopen.exit") after $(( $(date +%s) - start )) s"

echo "== our master against a python-canopen LocalNode (not our drive)"
cansend vcan0 7FF#FE
start=$(date +%s)
rm -f /run/pbvcan/foreign.ready
"$PYTHON" "$ROOT/tests/vcan/foreign_device.py" --iface vcan0 \
    --eds "$ROOT/tests/vcan/cia402-drive.eds" --node 1 --name "$FOREIGN_NAME" \
    --ready /run/pbvcan/foreign.ready > "$RESULTS/foreign-device.log" 2>&1 &
device_pid=$!
for _ in $(seq 300); do
    [ -f /run/pbvcan/foreign.ready ] && break
    sleep 0.1
done
timeout 120 "$FOREIGN_MASTER" --can vcan0 --machine "$ROOT/configs/machines/table-ac.toml" \
    --name "$FOREIGN_NAME" > "$RESULTS/foreign-master.log" 2>&1
echo $? > "$RESULTS/foreign-master.exit"
kill -TERM "$device_pid"
wait "$device_pid"
echo $? > "$RESULTS/foreign-device.exit"
echo "   master exit $(cat "$RESULTS/foreign-master.exit"), device exit" \
    "$(cat "$RESULTS/foreign-device.exit") after $(( $(date +%s) - start )) s"

echo "== conformance suite on SocketCAN (vcan0)"
cansend vcan0 7FF#FF
start=$(date +%s)
PROBEBRIDGE_TEST_CAN=vcan0 timeout 400 "$CONFORMANCE" --test-threads=1 \
    > "$RESULTS/conformance.log" 2>&1
echo $? > "$RESULTS/conformance.exit"
echo "   exit $(cat "$RESULTS/conformance.exit") after $(( $(date +%s) - start )) s"

sleep 0.5
kill "$candump_pid"
wait "$candump_pid" 2>/dev/null
cp /run/pbvcan/candump.log "$RESULTS/candump.log"
echo "vm: candump recorded $(wc -l < "$RESULTS/candump.log") frames"
date +%s > "$RESULTS/vm.done"
