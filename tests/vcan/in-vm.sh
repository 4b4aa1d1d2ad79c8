#!/usr/bin/env bash
# Runs inside the throwaway VM that .ci/vcan/run boots (the host's filesystem is
# visible read-only, RESULTS is the writable --rwdir). Brings up vcan0, records all
# traffic with candump, runs the cases of tests/vcan/cases against `probebridge sim`
# on vcan0, then the Machine conformance suite on the SocketCAN backend. Everything
# it finds goes into RESULTS; the host checks it (vng does not return the exit status).
#
# Usage: in-vm.sh RESULTS PROBEBRIDGE_BIN CONFORMANCE_TEST_EXE
set -u
RESULTS=$1
export PROBEBRIDGE_BIN=$2
CONFORMANCE=$3
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
export IOX2_LOG_LEVEL=${IOX2_LOG_LEVEL:-Error}
exec > "$RESULTS/vm.log" 2>&1
echo "vm: $(uname -r), $(nproc) cpus, $(awk '/MemTotal/ {print $2 " kB"}' /proc/meminfo)"
date +%s > "$RESULTS/vm.started"

if ! { modprobe vcan && ip link add dev vcan0 type vcan && ip link set vcan0 up; }; then
    echo "vm: cannot bring up vcan0" | tee "$RESULTS/vm.error"
    exit 1
fi
ip -details link show vcan0
# Room for a few seconds of traffic in every socket's receive queue: the emulated CPUs
# stall now and then, and a full queue drops frames silently (candump's included).
sysctl -q -w net.core.rmem_default=8388608 net.core.rmem_max=8388608
echo "vm: conformance suite: SYNC period ${PROBEBRIDGE_TEST_CAN_SYNC_US:-of the machine} us," \
    "heartbeat timeout ${PROBEBRIDGE_TEST_CAN_HEARTBEAT_TIMEOUT_MS:-of the machine} ms;" \
    "cases: configs from ${PROBEBRIDGE_VCAN_CONFIGS:-the repository}"

# The log grows by a few thousand frames a second: keep it in the VM's memory and
# copy it out at the end (the results folder is a synchronous 9p mount).
mkdir -p /run/pbvcan
candump -L vcan0 > /run/pbvcan/candump.log &
candump_pid=$!
sleep 0.5

bash "$ROOT/tests/vcan/run-cases.sh" "$RESULTS" vcan0

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
