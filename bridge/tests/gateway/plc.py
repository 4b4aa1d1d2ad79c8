"""A machine PLC playing against `probebridge serve`, written from the
register map of docs/gateway.md ("The PLC face: register map"). Usage: plc.py HOST PORT SCENARIO [ARGS]; prints one
JSON object on stdout; exits 1 with the failed check on stderr."""

import json
import socket
import struct
import sys
import time

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

REQ, SEQ, PROGRAM, FLAGS, PARAMS, HEARTBEAT = 0, 1, 2, 3, 4, 20
ACK_SEQ, ACK_CODE, REASON, STATE, BITS, PROGRESS, ERR_KIND, ERR_CODE, POINT = range(32, 41)
RES_HEAD, RES_REAL, RES_DINT, RES_TAIL = 64, 65, 197, 329
UNC_HEAD, UNC_REAL, UNC_TAIL = 330, 331, 463
CAL_HEAD, CAL_REAL, CAL_UNC, CAL_TAIL = 464, 465, 473, 481
CAL_COLUMNS = ("R", "CAL_OF1", "CAL_OF2", "L")
TIME_HEAD, TIME_TOTAL, TIME_TAIL = 482, 483, 493
TIME_PARTS = ("total", "positioning", "rotary", "probing", "standing")
START, ABORT, ACK = 1, 2, 3
IDLE, BUSY, DONE, ERROR, ABORTED = range(5)
NAMES = (
    [f"Q{n}" for n in range(141, 176)]
    + ["Q183"]
    + [f"{w}.{n}" for w in ("before", "after") for n in
       ("EY0A EZ0A EB0A EC0A EA0A EZ0B EX0B EC0B EA0B EB0B EX0C EY0C EA0C EB0C EC0C".split())]
)
TIMEOUT = 180.0


def check(cond, what):
    if not cond:
        print(f"FAILED: {what}", file=sys.stderr)
        sys.exit(1)


class Plc:
    def __init__(self, host, port):
        self.c = ModbusTcpClient(host, port=port)
        check(self.c.connect(), "connect")
        # Go on from the sequence the gateway acknowledged last (a PLC that restarted).
        self.seq = self.read(ACK_SEQ, 1)[0]
        self.hb = 0

    def read(self, addr, count):
        r = self.c.read_holding_registers(addr, count=count)
        check(not r.isError(), f"read {addr}+{count}: {r}")
        return r.registers

    def beat(self):
        self.hb = (self.hb + 1) & 0xFFFF
        r = self.c.write_register(HEARTBEAT, self.hb)
        check(not r.isError(), f"heartbeat write: {r}")

    def request(self, code, program=0, flags=0, params=()):
        self.seq = self.seq % 65535 + 1
        self.hb = (self.hb + 1) & 0xFFFF
        words = []
        for p in list(params) + [0.0] * (8 - len(params)):
            words += struct.unpack(">HH", struct.pack(">f", p))
        block = [code, self.seq, program, flags] + words + [self.hb]
        r = self.c.write_registers(REQ, block)
        check(not r.isError(), f"request write: {r}")
        # The handshake: wait until register 32 equals the sequence (a start is
        # answered once the gateway has prepared it: program, state, history row).
        return self.acknowledged(self.seq)

    def acknowledged(self, seq):
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            st = self.read(ACK_SEQ, 9)
            if st[0] == seq:
                return st
            time.sleep(0.005)
        check(False, f"acknowledge of seq {seq}")

    def state(self):
        return self.read(ACK_SEQ, 9)

    def wait(self, pred, beat=True):
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            if beat:
                self.beat()
            st = self.state()
            if pred(st):
                return st
        check(False, "timed out waiting")

    def results(self, seq):
        regs = self.read(64, 125) + self.read(189, 125) + self.read(314, 16)
        head, tail = regs[0], regs[RES_TAIL - 64]
        check(head == tail == seq, f"result sequence {head}/{tail} for request {seq}")
        real, dint = {}, {}
        for i, name in enumerate(NAMES):
            a = RES_REAL - 64 + 2 * i
            f = struct.unpack(">f", struct.pack(">HH", regs[a], regs[a + 1]))[0]
            if f == f:
                real[name] = f
            d = RES_DINT - 64 + 2 * i
            v = struct.unpack(">i", struct.pack(">HH", regs[d], regs[d + 1]))[0]
            if v != -(2 ** 31):
                dint[name] = v
        return real, dint

    def uncertainties(self, seq):
        regs = self.read(UNC_HEAD, 125) + self.read(UNC_HEAD + 125, UNC_TAIL - UNC_HEAD + 1 - 125)
        head, tail = regs[0], regs[UNC_TAIL - UNC_HEAD]
        check(head == tail == seq, f"uncertainty sequence {head}/{tail} for request {seq}")
        u = {}
        for i, name in enumerate(NAMES):
            a = UNC_REAL - UNC_HEAD + 2 * i
            f = struct.unpack(">f", struct.pack(">HH", regs[a], regs[a + 1]))[0]
            if f == f:
                u[name] = f
        return u


    def calibration(self, seq):
        regs = self.read(CAL_HEAD, CAL_TAIL - CAL_HEAD + 1)
        head, tail = regs[0], regs[CAL_TAIL - CAL_HEAD]
        check(head == tail == seq, f"calibration sequence {head}/{tail} for request {seq}")
        cal, cal_u = {}, {}
        for i, name in enumerate(CAL_COLUMNS):
            for base, out in ((CAL_REAL, cal), (CAL_UNC, cal_u)):
                a = base - CAL_HEAD + 2 * i
                f = struct.unpack(">f", struct.pack(">HH", regs[a], regs[a + 1]))[0]
                if f == f:
                    out[name] = f
        return cal, cal_u


    def machine_time(self, seq):
        regs = self.read(TIME_HEAD, TIME_TAIL - TIME_HEAD + 1)
        head, tail = regs[0], regs[TIME_TAIL - TIME_HEAD]
        check(head == tail == seq, f"machine time sequence {head}/{tail} for request {seq}")
        out = {}
        for i, name in enumerate(TIME_PARTS):
            a = TIME_TOTAL - TIME_HEAD + 2 * i
            out[name] = struct.unpack(">f", struct.pack(">HH", regs[a], regs[a + 1]))[0]
        return out


# Parameters 1..8 of every start of `run`: recorded with the run in the history.
PARAMS = (1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1000.125)


def run(plc, program):
    st = plc.request(START, program, flags=1, params=PARAMS)
    check(st[1] == START, f"start accepted: {st}")
    seq = plc.seq
    st = plc.wait(lambda s: s[3] != BUSY)
    check(st[3] == DONE, f"program {program} done: {st}")
    check(st[4] & 0b100100 == 0b100100, f"done and results-valid bits: {st[4]:#x}")
    real, dint = plc.results(seq)
    u = plc.uncertainties(seq)
    cal, cal_u = plc.calibration(seq)
    t = plc.machine_time(seq)
    cycle = plc.read(43, 1)[0]
    return {"cycle": cycle, "real": real, "dint": dint, "u": u, "cal": cal, "cal_u": cal_u,
            "time": t}


def last(plc):
    """The result, uncertainty and calibration blocks as they are: the last run's,
    whichever face started it (a run of the OPC UA face has the result sequence 0,
    which no PLC request has)."""
    seq = plc.read(RES_HEAD, 1)[0]
    real, dint = plc.results(seq)
    u = plc.uncertainties(seq)
    cal, cal_u = plc.calibration(seq)
    cycle = plc.read(43, 1)[0]
    return {"cycle": cycle, "seq": seq, "real": real, "dint": dint, "u": u, "cal": cal,
            "cal_u": cal_u}


def busy_abort(plc, program, other, again):
    st = plc.request(START, program, flags=1)
    check(st[1] == START, f"start accepted: {st}")
    start_seq = plc.seq
    plc.wait(lambda s: s[3] == BUSY and s[8] >= 1)
    st = plc.request(START, other)
    check(st[1] == START | 0x8000 and st[2] == 1, f"start while busy refused (busy): {st}")
    st = plc.request(ABORT)
    check(st[1] == ABORT, f"abort accepted: {st}")
    st = plc.wait(lambda s: s[3] != BUSY)
    check(st[3] == ABORTED and st[6] == 20, f"aborted by request: {st}")
    check(st[4] & 0b100100 == 0, f"neither done nor results valid: {st[4]:#x}")
    head, tail = plc.read(RES_HEAD, 1)[0], plc.read(RES_TAIL, 1)[0]
    check(head == tail == start_seq, "result sequence of the aborted run")
    aborted_at = st[8]
    # The abort is re-armed once the run has ended: the next measurement runs.
    check(st[4] & 0b10001 == 0b10001, f"ready and machine ok after the abort: {st[4]:#x}")
    after = run(plc, again)
    return {"aborted_at_point": aborted_at, "after": after}


def ack_error(plc, failing, good):
    st = plc.request(START, failing, flags=1)
    check(st[1] == START, f"start accepted: {st}")
    st = plc.wait(lambda s: s[3] != BUSY)
    check(st[3] == ERROR and st[6] != 0, f"program {failing} ends in error: {st}")
    check(st[4] & 0b1000 and not st[4] & 0b1, f"error bit, not ready: {st[4]:#x}")
    st = plc.request(START, good)
    check(st[1] == START | 0x8000 and st[2] == 5, f"start refused until acknowledged: {st}")
    st = plc.request(ACK)
    check(st[1] == ACK and st[3] == IDLE and st[6] == 0, f"acknowledged: {st}")
    check(st[4] & 0b1, f"ready after acknowledge: {st[4]:#x}")
    st = plc.request(START, 999)
    check(st[1] == START | 0x8000 and st[2] == 3, f"unknown program refused: {st}")
    return {"error_kind": 0}


def program_error(plc, program):
    """A program that stops itself with FN 14: ERROR = n: a failed run, the error kind
    and code registers as docs/gateway.md gives them, the results not valid."""
    st = plc.request(START, program, flags=1)
    check(st[1] == START, f"start accepted: {st}")
    st = plc.wait(lambda s: s[3] != BUSY)
    check(st[3] == ERROR, f"program {program} ends in error: {st}")
    check(st[4] & 0b100100 == 0, f"neither done nor results valid: {st[4]:#x}")
    return {"error_kind": st[6], "error_code": st[7]}


def run_unconfirmed(plc, program):
    """As `run`, with the confirm flag clear."""
    st = plc.request(START, program, flags=0)
    check(st[1] == START, f"start accepted: {st}")
    st = plc.wait(lambda s: s[3] != BUSY)
    return {"state": st[3], "error_kind": st[6], "error_code": st[7]}


def raw_read(host, port, addr, count):
    """FC3 as bytes on a socket of its own; the exception code, or None."""
    with socket.create_connection((host, port), timeout=10) as s:
        s.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, addr, count))
        head = s.recv(7)
        check(len(head) == 7, "MBAP header")
        body = s.recv(struct.unpack(">H", head[4:6])[0] - 1)
        return body[1] if body[0] == 0x83 else None


def second_connection(plc, host, port):
    plc.beat()  # the first connection owns the writes
    other = ModbusTcpClient(host, port=port)
    check(other.connect(), "second connect")
    r = other.write_register(HEARTBEAT, 7)
    check(r.isError() and r.exception_code == 6, f"second writer: ServerDeviceBusy: {r}")
    r = other.read_holding_registers(ACK_SEQ, count=9)
    check(not r.isError(), "second connection reads")
    other.close()
    r = plc.c.write_register(STATE, 1)
    check(r.isError() and r.exception_code == 2, f"read-only write: {r}")
    r = plc.c.write_register(25, 1)
    check(r.isError() and r.exception_code == 2, f"write outside the map: {r}")
    r = plc.c.read_holding_registers(21, count=1)
    check(r.isError() and r.exception_code == 2, f"read outside the map: {r}")
    # pymodbus refuses such counts itself: send the frames by hand.
    for count in (0, 126):
        code = raw_read(host, port, 64, count)
        check(code == 3, f"read of {count} registers: exception {code}")
    return {}


def heartbeat_loss(plc, program):
    st = plc.request(START, program, flags=1)
    check(st[1] == START, f"start accepted: {st}")
    plc.wait(lambda s: s[3] == BUSY and s[8] >= 1)
    st = plc.wait(lambda s: s[3] != BUSY, beat=False)
    check(st[3] == ABORTED and st[6] == 21, f"aborted for the PLC heartbeat: {st}")
    return {}


def start_busy(plc, program):
    st = plc.request(START, program, flags=1)
    check(st[1] == START, f"start accepted: {st}")
    plc.wait(lambda s: s[3] == BUSY and s[8] >= 1)
    return {}


def connect_patiently(host, port, deadline):
    """Connects until a connection answers a read (the gateway may close new connections
    while its limit is reached); the PLC and the number of attempts."""
    attempts = 0
    while time.monotonic() < deadline:
        attempts += 1
        c = ModbusTcpClient(host, port=port, retries=0, timeout=2)
        if c.connect():
            try:
                r = c.read_holding_registers(ACK_SEQ, count=1)
            except (ModbusException, OSError):
                r = None
            if r is not None and not r.isError():
                plc = Plc.__new__(Plc)
                plc.c, plc.seq, plc.hb = c, r.registers[0], 0
                return plc, attempts
        c.close()
        time.sleep(0.2)
    check(False, f"no connection answered within the deadline ({attempts} attempts)")


def patient_run(host, port, program):
    """A PLC that retries: connects until served, repeats its start while the request
    block is another connection's (ServerDeviceBusy), then runs `program`."""
    deadline = time.monotonic() + 60
    plc, attempts = connect_patiently(host, port, deadline)
    busy = 0
    seq = plc.seq = plc.seq % 65535 + 1
    words = []
    for p in PARAMS:
        words += struct.unpack(">HH", struct.pack(">f", p))
    while True:
        r = plc.c.write_registers(REQ, [START, seq, program, 1] + words + [plc.hb])
        if not r.isError():
            break
        check(r.exception_code == 6, f"start refused with exception {r.exception_code}")
        check(time.monotonic() < deadline, f"still busy after {busy} refusals")
        busy += 1
        time.sleep(0.2)
    st = plc.wait(lambda s: s[0] == seq)
    check(st[1] == START, f"start accepted: {st}")
    st = plc.wait(lambda s: s[3] != BUSY)
    check(st[3] == DONE, f"program {program} done: {st}")
    real, dint = plc.results(seq)
    return {"cycle": plc.read(43, 1)[0], "real": real, "connect_attempts": attempts,
            "busy_refusals": busy}


def machine_lost(plc, program):
    """The gateway lost its machine: "machine ok" and "ready" drop, a start is refused
    with the reason "machine not ok" (8)."""
    st = plc.wait(lambda s: not s[4] & 0b10000)
    check(not st[4] & 0b1, f"not ready without the machine: {st[4]:#x}")
    st = plc.request(START, program, flags=1)
    check(st[1] == START | 0x8000 and st[2] == 8, f"start refused, machine not ok: {st}")
    return {"bits": st[4]}


def machine_back(plc, program):
    """The gateway has its machine again: "machine ok" comes back and a run is done."""
    st = plc.wait(lambda s: s[4] & 0b10001 == 0b10001)
    return run(plc, program)


def main():
    host, port, scenario = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    args = [int(a) for a in sys.argv[4:]]
    if scenario == "patient_run":
        print(json.dumps(patient_run(host, port, args[0])))
        return
    plc = Plc(host, port)
    if scenario == "run":
        out = run(plc, args[0])
    elif scenario == "last":
        out = last(plc)
    elif scenario == "busy_abort":
        out = busy_abort(plc, args[0], args[1], args[2])
    elif scenario == "ack_error":
        out = ack_error(plc, args[0], args[1])
    elif scenario == "program_error":
        out = program_error(plc, args[0])
    elif scenario == "run_unconfirmed":
        out = run_unconfirmed(plc, args[0])
    elif scenario == "second_connection":
        out = second_connection(plc, host, port)
    elif scenario == "state":
        st = plc.state()
        out = {"state": st[3], "bits": st[4]}
    elif scenario == "start_busy":
        out = start_busy(plc, args[0])
    elif scenario == "machine_lost":
        out = machine_lost(plc, args[0])
    elif scenario == "machine_back":
        out = machine_back(plc, args[0])
    elif scenario == "heartbeat_loss":
        out = heartbeat_loss(plc, args[0])
    else:
        check(False, f"unknown scenario {scenario}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
