# Sourced by the scripts that try `serve` as a gateway runs it, with a PLC in Python
# (scripts/arm64-equivalence, scripts/gateway-footprint). Run from the clone's root.

# gateway_python WORK: prints a Python that has pymodbus: $PROBEBRIDGE_PYTHON, else
# the test peers' venv (scripts/install-test-peers), else WORK/venv, made with the
# pymodbus version scripts/install-test-peers pins.
gateway_python() {
    local work=$1 py=${PROBEBRIDGE_PYTHON:-/opt/probebridge-venv/bin/python} version
    if "$py" -c 'import pymodbus' 2>/dev/null; then echo "$py"; return; fi
    py=$work/venv/bin/python
    if ! "$py" -c 'import pymodbus' 2>/dev/null; then
        version=$(sed -n 's/^PYMODBUS_VERSION=\(.*\)$/\1/p' scripts/install-test-peers | tr -d '"')
        echo "making $work/venv with pymodbus $version" >&2
        python3 -m venv "$work/venv" >&2
        "$work/venv/bin/pip" install -q "pymodbus==$version" >&2
    fi
    echo "$py"
}

# gateway_config DIR SERVICE: DIR/gateway.toml for `serve` on the simulated tilted
# plane (iceoryx2 service SERVICE), the PLC face on a free port of 127.0.0.1 without a
# heartbeat, the history in DIR; program 431 is configs/programs/431-plane.h.
gateway_config() {
    local dir=$1 service=$2
    mkdir -p "$dir/programs"
    cp configs/programs/431-plane.h "$dir/programs/431.h"
    cat >"$dir/gateway.toml" <<TOML
[machine]
scenario = "$(pwd)/configs/scenarios/tilted-plane.toml"
service = "$service"
[programs]
folder = "programs"
[plc]
listen = "127.0.0.1:0"
heartbeat_timeout_ms = 0
[history]
sqlite = "$dir/history.sqlite"
TOML
}

# serve_port DIR PID WHO: waits until the `serve` of PID (started with its stdout in
# DIR/stdout and its stderr in DIR/serve.log) says where it listens, which it does once
# the machine is up; prints the PLC face's port. Exits with serve's log, as WHO, when
# serve ends first.
serve_port() {
    local dir=$1 pid=$2 who=$3
    until grep -q '^probebridge serve: listening on ' "$dir/stdout" 2>/dev/null; do
        kill -0 "$pid" 2>/dev/null || { echo "$who: serve ended:" >&2; cat "$dir/serve.log" >&2; exit 1; }
        sleep 0.05
    done
    sed -n 's/^probebridge serve: listening on .*:\([0-9]*\)$/\1/p' "$dir/stdout"
}
