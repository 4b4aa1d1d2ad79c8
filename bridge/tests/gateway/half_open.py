"""A PLC that loses power while it owns the request block, played in network namespaces
this script makes (run it inside `unshare -rn`: the gateway's namespace).

The PLC lives in a namespace of its own joined to the gateway's by a veth pair
(gateway 10.77.0.1, PLC 10.77.0.2). It writes one register (it owns the block); then
the link is deleted and the PLC's processes die, so no FIN or RST ever reaches the
gateway: its socket stays ESTABLISHED, as after a power loss. The PLC "reboots" (a new
namespace and link, same address) and runs a program.

Usage: half_open.py PROBEBRIDGE GATEWAY.toml PLC.py PROGRAM LOG
(GATEWAY.toml listens on 10.77.0.1:0). Prints one JSON object; exits 1 with the
failed check on stderr. `half_open.py --own HOST PORT` is the PLC's first life."""

import json
import os
import re
import signal
import subprocess
import sys
import time

GATEWAY, PLC = "10.77.0.1", "10.77.0.2"


def check(cond, what):
    if not cond:
        print(f"FAILED: {what}", file=sys.stderr)
        sys.exit(1)


def sh(*cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    check(r.returncode == 0, f"{' '.join(cmd)}: {r.stderr.strip()}")
    return r.stdout


def plc_namespace():
    """A process holding a new network namespace, joined to ours by gw0/plc0."""
    ns = subprocess.Popen(["unshare", "-n", "sleep", "600"])
    # The namespace exists once the process has exec'd sleep.
    deadline = time.monotonic() + 30
    while os.readlink(f"/proc/{ns.pid}/ns/net") == os.readlink("/proc/self/ns/net"):
        check(time.monotonic() < deadline, "the PLC namespace did not appear")
        time.sleep(0.01)
    sh("ip", "link", "add", "gw0", "type", "veth", "peer", "name", "plc0")
    sh("ip", "link", "set", "plc0", "netns", str(ns.pid))
    sh("ip", "addr", "add", f"{GATEWAY}/24", "dev", "gw0")
    sh("ip", "link", "set", "gw0", "up")
    inside = ["nsenter", "-t", str(ns.pid), "-n"]
    sh(*inside, "ip", "link", "set", "lo", "up")
    sh(*inside, "ip", "addr", "add", f"{PLC}/24", "dev", "plc0")
    sh(*inside, "ip", "link", "set", "plc0", "up")
    return ns, inside


def established(port):
    """The gateway's ESTABLISHED connections on its PLC port (ss)."""
    out = sh("ss", "-Htn", "state", "established", f"( sport = :{port} )")
    return [line for line in out.splitlines() if line.strip()]


def own(host, port):
    from pymodbus.client import ModbusTcpClient

    c = ModbusTcpClient(host, port=int(port))
    check(c.connect(), "connect")
    r = c.write_register(20, 1)
    check(not r.isError(), f"heartbeat write: {r}")
    print("owned", flush=True)
    time.sleep(600)


def main():
    if sys.argv[1] == "--own":
        own(sys.argv[2], sys.argv[3])
        return
    binary, config, plc_py, program, log = sys.argv[1:6]
    sh("ip", "link", "set", "lo", "up")
    ns, inside = plc_namespace()
    env = dict(os.environ, PROBEBRIDGE_LOG="debug")
    serve = subprocess.Popen([binary, "serve", "--config", config], stdout=subprocess.PIPE,
                             stderr=open(log, "w"), env=env, text=True)
    rebooted = None
    try:
        line = serve.stdout.readline()
        m = re.match(r"probebridge serve: listening on .*:(\d+)$", line.strip())
        check(m, f"serve did not come up: {line!r}")
        port = m.group(1)
        owner = subprocess.Popen(inside + [sys.executable, __file__, "--own", GATEWAY, port],
                                 stdout=subprocess.PIPE, text=True)
        check(owner.stdout.readline().strip() == "owned", "the first PLC owns the block")
        # Power loss: the wire first, then the PLC; nothing reaches the gateway.
        sh("ip", "link", "del", "gw0")
        owner.kill()
        owner.wait()
        ns.kill()
        ns.wait()
        half_open = established(port)
        check(len(half_open) == 1, f"one half-open connection at the gateway: {half_open}")
        # The PLC boots again with the same address and starts a run at once.
        rebooted, inside = plc_namespace()
        r = subprocess.run(inside + [sys.executable, plc_py, GATEWAY, port, "patient_run",
                                     program],
                           capture_output=True, text=True)
        check(r.returncode == 0, f"the rebooted PLC's run: {r.stderr.strip()}")
        result = json.loads(r.stdout)
        # The dead connection goes: keepalive probes reach the rebooted PLC, whose
        # kernel answers with a reset.
        deadline = time.monotonic() + 60
        while not re.search(r"connection 1 of [0-9.:]+ closed", open(log).read()):
            check(time.monotonic() < deadline,
                  f"connection 1 still open 60 s later: {established(port)}")
            time.sleep(0.1)
        print(json.dumps({"cycle": result["cycle"], "half_open": half_open,
                          "busy_refusals": result["busy_refusals"]}))
    finally:
        serve.send_signal(signal.SIGTERM)
        serve.wait()
        for p in (ns, rebooted):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()


if __name__ == "__main__":
    main()
