"""A PLC for the history fault tests (`bridge/tests/history_faults.rs`), on top of
`plc.py`: each call is one short connection, so the test can break the history
between the start of a run and its end.

Usage: history_plc.py HOST PORT start PROGRAM | end SEQ | abort | state
Prints one JSON object: the state block (and for `start` the sequence used and the milliseconds until its answer, for `end`
of a done run its REAL results)."""

import json
import sys
import time

from plc import ABORT, BUSY, DONE, START, Plc, check


def state(plc):
    st = plc.state()
    return {
        "ack_seq": st[0],
        "ack_code": st[1],
        "reason": st[2],
        "state": st[3],
        "bits": st[4],
        "error_kind": st[6],
        "point": st[8],
    }


def main():
    host, port, cmd = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    plc = Plc(host, port)
    if cmd == "start":
        t = time.monotonic()
        plc.request(START, int(sys.argv[4]), flags=1)
        out = state(plc)
        out["answer_ms"] = round((time.monotonic() - t) * 1000, 1)
        out["seq"] = plc.seq
    elif cmd == "end":
        seq = int(sys.argv[4])
        plc.wait(lambda s: s[3] != BUSY)
        out = state(plc)
        if out["state"] == DONE:
            real, _ = plc.results(seq)
            out["results"] = real
    elif cmd == "abort":
        plc.request(ABORT)
        out = state(plc)
    elif cmd == "state":
        out = state(plc)
    else:
        check(False, f"unknown command {cmd}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
