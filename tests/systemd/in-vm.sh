#!/bin/bash
# Runs inside the systemd VM of .ci/systemd/run (Debian 12, systemd as PID 1), as the
# oneshot unit probebridge-ci.service, as root, with the clone's tracked files at
# /root/probebridge, the package to install in /root/packages and a package of a
# higher version in /root/upgrade (both of the release binary built on the host, by
# scripts/package --binary; their versions in /root/packages/versions). Writes its log to /root/ci/vm.log and one
# line per check to /root/ci/checks ("ok NAME" or "FAIL NAME"), then "end"; the unit
# then powers the VM off and the host reads both from the disk image.
#
# 1. A local user (mallory) squats the shared /tmp first: she holds the lock file the
#    gateway used to take there and owns /tmp/iceoryx2.
# 2. The "Deploy on a gateway" block of docs/deploy.md, extracted from it and run line
#    by line as written, in /root/packages (the block is the test: the docs cannot
#    drift): `apt install` of the package, ..., `systemctl enable --now`. One line
#    cannot run as written without a terminal: `journalctl ... -f` runs for 10 s.
#    Installed: nothing started or enabled by the package itself.
# 3. `systemctl enable --now` returned after READY=1 (Type=notify): the unit is
#    active, its STATUS is the gateway's, the lock and the iceoryx2 root are in
#    /run/probebridge, gateway.toml is 640 root:probebridge.
# 4. gateway.toml edited as docs/deploy.md says ([machine]: the tilted-plane simulator in
#    real time, so a stop lands mid-measurement; [plc]: heartbeat off, so only the
#    stop ends it), a 431 program added, the machine's SYNC and heartbeat timing
#    relaxed as in the vcan step (emulated CPUs); the PLC client (bridge/tests/gateway/plc.py,
#    pymodbus) runs a 431 through the installed unit; the history says done.
# 5. `systemctl kill -s SIGKILL`: Restart= brings it back (new main pid), a 431 runs
#    again (the count of iceoryx2 files in /dev/shm before and after is printed).
# 6. The main process SIGSTOPped (a wedged service, fed no watchdog): systemd's
#    watchdog (WatchdogSec=) kills it and Restart= brings it back.
#    A wedged PLC face (its thread blocked): the service ends itself, Restart= brings
#    it back.
# 6c. The upgrade to the higher version, its postinst run during a measurement. The service
#    restarts after the measurement (SIGUSR1 from the postinst, exit 75): the run ends
#    done, the new main process serves; the edited gateway.toml, machine file and
#    program and the history are kept; a 431 runs after it.
# 7. `systemctl stop` during a 431: the run ends "aborted" (Aborted(Shutdown)), exit 0.
# 8. `systemd-analyze security probebridge`, printed.
# 9. `apt remove` with the service running: stopped, the binary gone, /etc/probebridge,
#    /var/lib/probebridge and the user kept. `apt purge`: those gone too.
set -uo pipefail
CLONE=/root/probebridge
OUT=/root/ci
PLC_PY=$CLONE/bridge/tests/gateway/plc.py
export PYTHONPATH=/opt/plc-python
mkdir -p "$OUT"
exec > >(tee -a "$OUT/vm.log") 2>&1

say() { echo "ci: $*"; }
check() {
    local name=$1
    shift
    if "$@"; then
        echo "ok $name" >>"$OUT/checks"
        say "ok: $name"
    else
        echo "FAIL $name" >>"$OUT/checks"
        say "FAILED: $name"
    fi
}
prop() { systemctl show -p "$1" --value probebridge; }
# Waits up to $1 s until the unit is active with a main pid other than $2.
back_with_new_pid() {
    local limit=$1 old=$2 i pid
    for ((i = 0; i < limit * 2; i++)); do
        pid=$(prop MainPID)
        if [ "$(prop ActiveState)" = active ] && [ "$pid" != 0 ] && [ "$pid" != "$old" ]; then
            say "active again, main pid $pid (was $old), NRestarts=$(prop NRestarts)"
            return 0
        fi
        sleep 0.5
    done
    say "not back within $limit s: $(systemctl status --no-pager probebridge 2>&1 | head -20)"
    return 1
}
plc() { python3 "$PLC_PY" 127.0.0.1 5020 "$@"; }
history_json() {
    runuser -u probebridge -- probebridge history --config /etc/probebridge/gateway.toml \
        --since 2000-01-01 --json
}
history_last_status() {
    history_json | python3 -c 'import json,sys; print(json.load(sys.stdin)[-1]["status"])'
}
history_count() {
    history_json | python3 -c 'import json,sys; print(len(json.load(sys.stdin)))'
}
installed_version() { dpkg-query -W -f='${Status} ${Version}' probebridge 2>/dev/null; }
finish() {
    say "the service's journal:"
    journalctl -u probebridge --no-pager | tail -n 80
    echo end >>"$OUT/checks"
    say "done"
    sync
    exit 0 # the unit's SuccessAction= powers the VM off
}

say "kernel $(uname -r), $(systemctl --version | head -1), PID 1 is $(cat /proc/1/comm)"
check "pid-1-is-systemd" test "$(cat /proc/1/comm)" = systemd

# 1. The squatter.
useradd --create-home mallory
runuser -u mallory -- mkdir -m 700 /tmp/iceoryx2
runuser -u mallory -- touch /tmp/probebridge-service-probebridge.lock
runuser -u mallory -- flock /tmp/probebridge-service-probebridge.lock sleep 100000 &
squatter=$!

# 2. The deploy block of docs/deploy.md.
read -r VERSION UPGRADE_VERSION </root/packages/versions
say "packages: $(ls /root/packages /root/upgrade | tr '\n' ' ')"
block=$(awk '/^# Deploy on a gateway/ {s = 1; next}
    s && /^#/ {exit}
    s && /^    / {print substr($0, 5); b = 1; next}
    s && b {exit}' "$CLONE/docs/deploy.md")
say "the deploy block of docs/deploy.md:"
printf '%s\n' "$block" | sed 's/^/    /'
check "readme-block-found" grep -q 'systemctl enable --now probebridge' <<<"$block"
cd /root/packages
deploy_ok=true
while IFS= read -r line; do
    say "\$ $line"
    case "$line" in
    journalctl*" -f")
        timeout 10 bash -c "$line"
        rc=$?
        [ "$rc" = 124 ] && rc=0
        ;;
    *)
        bash -e -c "$line" </dev/null
        rc=$?
        ;;
    esac
    case "$line" in
    "apt install "*)
        # What the package alone did, before the plant enables it.
        check "package-installed" test "$(installed_version)" = "install ok installed $VERSION"
        check "package-not-started" test "$(systemctl is-active probebridge)" = inactive
        check "package-not-enabled" test "$(systemctl is-enabled probebridge)" = disabled
        check "package-user" getent passwd probebridge
        check "package-documentation-resolves" test -f /usr/share/doc/probebridge/docs/deploy.md
        check "package-man-page" test -f /usr/share/man/man1/probebridge-serve.1.gz
        ;;
    esac
    if [ "$rc" != 0 ]; then
        say "exit status $rc"
        deploy_ok=false
        break
    fi
done <<<"$block"
check "readme-deploy-steps" $deploy_ok
if ! $deploy_ok; then
    systemctl status --no-pager probebridge
    journalctl -u probebridge --no-pager | tail -40
    finish
fi

# 3. Started through READY=1.
say "ActiveState=$(prop ActiveState) SubState=$(prop SubState) Type=$(prop Type) StatusText=$(prop StatusText)"
check "active" test "$(systemctl is-active probebridge)" = active
check "type-notify" test "$(prop Type)" = notify
check "status-after-ready" grep -q '^idle, PLC face on 127.0.0.1:5020' <<<"$(prop StatusText)"
ls -la /run/probebridge /run/probebridge/iceoryx2
check "lock-in-runtime-directory" test -f /run/probebridge/probebridge-service-probebridge.lock
check "iceoryx2-root-in-runtime-directory" test -d /run/probebridge/iceoryx2
check "squatted-tmp-untouched" test -z "$(ls -A /tmp/iceoryx2)"
check "gateway-toml-640-probebridge" test "$(stat -c %a:%U:%G /etc/probebridge/gateway.toml)" = 640:root:probebridge
ls -l /etc/probebridge/gateway.toml

# 4. A 431 from the PLC.
sed -i -e 's|^scenario = .*|scenario = "scenarios/tilted-plane.toml"\nrealtime = true|' \
    -e 's|^heartbeat_timeout_ms = .*|heartbeat_timeout_ms = 0|' /etc/probebridge/gateway.toml
grep -E '^(scenario|realtime|heartbeat_timeout_ms) ' /etc/probebridge/gateway.toml
cp /etc/probebridge/programs/431-plane.h /etc/probebridge/programs/431.h
# As in the vcan step: the emulated CPUs cannot hold a 2 ms SYNC with a 150 ms
# heartbeat timeout in real time; the machine's timing is relaxed to the same values
# (.ci/lib/vm-timing.sh; the results do not depend on it).
source "$CLONE/.ci/lib/vm-timing.sh"
sed -i -e "s/^sync_period_us *=.*/sync_period_us = $VM_SYNC_US/" \
    -e "s/^heartbeat_timeout_ms *=.*/heartbeat_timeout_ms = $VM_HEARTBEAT_TIMEOUT_MS/" \
    -e "s/^master_heartbeat_ms *=.*/master_heartbeat_ms = $VM_MASTER_HEARTBEAT_MS/" /etc/probebridge/machines/table-ac.toml
grep -E '^(sync_period_us|heartbeat_timeout_ms|master_heartbeat_ms) ' /etc/probebridge/machines/table-ac.toml
systemctl restart probebridge
check "restarted-active" test "$(systemctl is-active probebridge)" = active
run431() {
    local out
    out=$(plc run 431) || return 1
    say "PLC: ${out:0:300}"
    python3 -c 'import json,sys; sys.exit(json.loads(sys.argv[1])["cycle"] != 431)' "$out"
}
check "plc-runs-431" run431
check "history-done" test "$(history_last_status)" = done

# 4b. The OPC UA face, as docs/opcua.md and docs/deploy.md deploy it: the users file (argon2id hashes,
#     mode 600, the service's user), [opcua] in gateway.toml; its port answers, its
#     certificate is made in the state directory on the first start (key mode 600) and
#     kept over a restart; the PLC's 431 still runs with it on.
ua=/var/lib/probebridge/opcua
install -d -m 700 -o probebridge -g probebridge "$ua"
printf '%s\n' 'a long pass phrase' | probebridge opcua-user mes \
    | install -m 600 -o probebridge -g probebridge /dev/stdin "$ua/users"
printf '\n[opcua]\nlisten = "opc.tcp://127.0.0.1:4840"\nmay_start = true\n' >>/etc/probebridge/gateway.toml
systemctl restart probebridge
check "opcua-restarted-active" test "$(systemctl is-active probebridge)" = active
check "opcua-port-answers" bash -c 'exec 3<>/dev/tcp/127.0.0.1/4840'
check "opcua-certificate-made" test -s "$ua/pki/own/cert.der"
check "opcua-key-600-probebridge" test "$(stat -c %a:%U "$ua/pki/private/private.pem")" = 600:probebridge
ls -lR "$ua"
cert_before=$(sha256sum <"$ua/pki/own/cert.der")
systemctl restart probebridge
check "opcua-certificate-kept" test "$(sha256sum <"$ua/pki/own/cert.der")" = "$cert_before"
check "opcua-in-journal" grep -q "OPC UA face ready" <<<"$(journalctl -u probebridge --no-pager)"
check "plc-runs-431-with-opcua" run431

# 5. SIGKILL.
pid=$(prop MainPID)
shm_before=$(find /dev/shm -name 'iox2_*' | wc -l)
systemctl kill -s SIGKILL probebridge
check "sigkill-restarted" back_with_new_pid 120 "$pid"
check "plc-runs-431-after-sigkill" run431
# The killed processes' iceoryx2 shared memory should be removed by the next start
# (their node records survive the restart: RuntimeDirectoryPreserve=restart); printed,
# not checked.
shm_after=$(find /dev/shm -name 'iox2_*' | wc -l)
say "iceoryx2 files in /dev/shm: $shm_before before the kill, $shm_after after the restart and a 431"

# 6. The watchdog.
pid=$(prop MainPID)
say "SIGSTOP to main pid $pid; WatchdogUSec=$(prop WatchdogUSec)"
systemctl kill -s SIGSTOP --kill-whom=main probebridge
check "watchdog-restarted" back_with_new_pid 180 "$pid"
check "watchdog-in-journal" grep -q "Watchdog timeout" <<<"$(journalctl -u probebridge --no-pager)"

# 6b. A wedged PLC face in a service that is otherwise alive (the face's thread blocked
#     by the test-only fault switch, set through a runtime drop-in): the watchdog is no
#     longer fed, the service ends itself ("the PLC face is dead", exit 1) and Restart=
#     brings it back; with the drop-in gone, it serves a 431 again.
dropin=/run/systemd/system/probebridge.service.d
mkdir -p "$dropin"
printf '[Service]\nEnvironment=PROBEBRIDGE_FAULT_PLC_FACE=stall\n' >"$dropin/wedge.conf"
systemctl daemon-reload
systemctl restart probebridge
n0=$(prop NRestarts)
face_died_and_restarted() {
    local i
    for ((i = 0; i < 240; i++)); do
        if [ "$(prop NRestarts)" -gt "$n0" ] \
            && journalctl -u probebridge --no-pager | grep -q "the PLC face is dead"; then
            say "wedged face: restarted by systemd, NRestarts $n0 -> $(prop NRestarts)"
            return 0
        fi
        sleep 0.5
    done
    journalctl -u probebridge --no-pager | tail -20
    return 1
}
check "wedged-face-restarted" face_died_and_restarted
rm -f "$dropin/wedge.conf"
systemctl daemon-reload
systemctl restart probebridge
check "plc-runs-431-after-wedge" run431

# 6c. The upgrade, during a measurement.
sums() { sha256sum /etc/probebridge/gateway.toml /etc/probebridge/machines/table-ac.toml /etc/probebridge/programs/431.h; }
sums_before=$(sums)
runs_before=$(history_count)
pid=$(prop MainPID)
# The two halves of `apt install` (it runs dpkg --unpack, then dpkg --configure), with
# a measurement started between them, 431 three times (program 432, a section repeat):
# the postinst's restart lands during it (here `apt install` in one go took longer
# than a 431, and `dpkg --configure` about 10 s).
{
    echo "0 BEGIN PGM 432 MM"
    echo '1 TOOL CALL "TOUCH_PROBE" Z'
    echo "2 L Z+100 R0 FMAX"
    echo "3 LBL 1"
    sed -n '/^6 TCH PROBE 431/,/Q281/p' /etc/probebridge/programs/431-plane.h | sed 's/^6 /4 /'
    echo "5 L Z+100 R0 FMAX"
    echo "6 CALL LBL 1 REP 2"
    echo "7 M30"
    echo "8 END PGM 432 MM"
} >/etc/probebridge/programs/432.h
say "\$ dpkg --unpack ./probebridge_${UPGRADE_VERSION}_amd64.deb"
(cd /root/upgrade && dpkg --unpack "./probebridge_${UPGRADE_VERSION}_amd64.deb" </dev/null)
check "upgrade-plc-start-busy" plc start_busy 432
say "\$ dpkg --configure probebridge (during the measurement)"
dpkg --configure probebridge </dev/null
check "upgrade-installed" test "$(installed_version)" = "install ok installed $UPGRADE_VERSION"
check "upgrade-restarted" back_with_new_pid 180 "$pid"
journal=$(journalctl -u probebridge --no-pager)
check "upgrade-restart-after-the-measurement" grep -q "restart asked (SIGUSR1): after the running measurement" <<<"$journal"
check "upgrade-restart-asked" grep -q "restarting as asked (SIGUSR1)" <<<"$journal"
check "upgrade-run-done" test "$(history_last_status)" = done
check "upgrade-history-kept" test "$(history_count)" = $((runs_before + 1))
check "upgrade-edits-kept" test "$(sums)" = "$sums_before"
check "plc-runs-431-after-upgrade" run431

# 7. systemctl stop mid-measurement.
check "plc-start-busy" plc start_busy 431
check "stop" systemctl stop probebridge
check "stopped-inactive" test "$(systemctl is-active probebridge)" = inactive
check "exit-0" test "$(prop ExecMainStatus)" = 0
check "history-aborted" test "$(history_last_status)" = aborted
journalctl -u probebridge --no-pager | tail -15
check "journal-aborted-by-shutdown" grep -q "Aborted(Shutdown)" <<<"$(journalctl -u probebridge --no-pager)"

# 8. The sandbox, as systemd rates it.
systemd-analyze security --no-pager probebridge | tee "$OUT/security.txt"

# 9. Remove, then purge.
systemctl start probebridge
check "running-before-remove" test "$(systemctl is-active probebridge)" = active
say "\$ apt remove -y probebridge"
apt remove -y probebridge </dev/null
check "removed" test "$(installed_version)" = "deinstall ok config-files $UPGRADE_VERSION"
check "removed-stopped" test "$(systemctl is-active probebridge)" != active
check "removed-binary-gone" test ! -e /usr/bin/probebridge
check "removed-keeps-config" test "$(sums)" = "$sums_before"
check "removed-keeps-history" test -s /var/lib/probebridge/history.sqlite
check "removed-keeps-user" getent passwd probebridge
say "\$ apt purge -y probebridge"
apt purge -y probebridge </dev/null
check "purged" test -z "$(installed_version | grep -v 'not-installed')"
check "purged-config-gone" test ! -e /etc/probebridge
check "purged-state-gone" test ! -e /var/lib/probebridge
check "purged-user-gone" bash -c '! getent passwd probebridge && ! getent group probebridge'
ls -la /etc/probebridge /var/lib/probebridge 2>&1 | head -5

kill "$squatter" 2>/dev/null
finish
