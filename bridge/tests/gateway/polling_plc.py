"""A PLC that polls its state every 10 ms while its start is prepared
(`bridge/tests/serve_slow_history.rs`): the gateway must go on answering while the
history it writes the run's `running` row into is held by the test.

Usage: polling_plc.py HOST PORT PROGRAM N
Writes the start request, then reads the state block every 10 ms. Prints
`pending N` (flushed) once N reads were answered while the start was not yet
acknowledged, then goes on polling until it is, waits for the end of the run, and
prints one JSON object: the reads answered before the acknowledge, the acknowledge, the
state at the end, and the longest read (ms, for the log)."""

import json
import sys
import time

from plc import BUSY, REQ, START, Plc, check


def main():
    host, port, program, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    plc = Plc(host, port)
    plc.seq = plc.seq % 65535 + 1
    r = plc.c.write_registers(REQ, [START, plc.seq, program, 1] + [0] * 16 + [plc.hb])
    check(not r.isError(), f"request write: {r}")
    pending, longest = 0, 0.0
    deadline = time.monotonic() + 120
    while True:
        check(time.monotonic() < deadline, f"start never acknowledged ({pending} reads)")
        t = time.monotonic()
        st = plc.state()
        longest = max(longest, time.monotonic() - t)
        if st[0] == plc.seq:
            break
        pending += 1
        if pending == n:
            print(f"pending {n}", flush=True)
        time.sleep(0.01)
    out = {"pending_reads": pending, "ack_code": st[1], "reason": st[2],
           "longest_read_ms": round(longest * 1000, 1)}
    if st[1] == START:
        st = plc.wait(lambda s: s[3] != BUSY)
    out["state"] = st[3]
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
