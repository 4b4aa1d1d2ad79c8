#!/usr/bin/env python3
"""An independent PLC double for probebridge's Modbus backend, written from the
mailbox tables of docs/modbus.md ("The mailbox"), not from the Rust code.

A pymodbus TCP server (127.0.0.1, port 0; the first stdout line is
"modbus tcp 127.0.0.1:PORT") holding the mailbox at the default layout: command
block at 0 (20 registers), status block at 100 (22), latch ring at 200 (4 slots of
18). The world is one plane (material on the side opposite its normal) and a stylus
ball of radius R: the probe deflects when the ball centre is within R of the plane.
Moves run in the double's own time, SPEEDUP times faster than the wall clock, in
1 ms cycles; the latch is the exact crossing point of the cycle's segment.

With --spindle the double has an orientable spindle (command 5, orient spindle): it
takes the angle from the first target's registers, answers done with result 0 and
prints "orient ANGLE_MILLIDEG" on stdout; without it, command 5 is rejected (7).

Usage: plc_double.py --plane PX,PY,PZ,NX,NY,NZ --radius R [--word-order CDAB] [--spindle]
"""

import argparse
import asyncio
import math

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.datastore.context import ModbusBaseDeviceContext
from pymodbus.server import ModbusTcpServer

CMD, STATUS, RING, SLOTS, SLOT = 0, 100, 200, 4, 18
COUNTS = 1_000_000.0  # counts per mm and per degree
CYCLE_S = 0.001
SPEEDUP = 50.0

# result codes and status bits as the tables of docs/modbus.md give them
OK, CONTACT, NOT_TRIGGERED, ALREADY_DEFLECTED, COLLISION = 0, 1, 2, 3, 4
REJECTED = 7
READY, BUSY, IN_POSITION, DEFLECTED, ARMED = 1, 2, 4, 8, 16


def put32(order, v):
    v &= 0xFFFFFFFF
    a, b, c, d = (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF, v & 0xFF
    return {
        "ABCD": [a << 8 | b, c << 8 | d],
        "CDAB": [c << 8 | d, a << 8 | b],
        "BADC": [b << 8 | a, d << 8 | c],
        "DCBA": [d << 8 | c, b << 8 | a],
    }[order]


def get32(order, r):
    x, y = r
    hi, lo = {
        "ABCD": (x, y),
        "CDAB": (y, x),
        "BADC": (swap(x), swap(y)),
        "DCBA": (swap(y), swap(x)),
    }[order]
    v = hi << 16 | lo
    return v - (1 << 32) if v & 0x80000000 else v


def swap(w):
    return (w & 0xFF) << 8 | w >> 8


class Plc(ModbusBaseDeviceContext):
    def __init__(self, plane, radius, order, spindle=False):
        self.point, n = plane[:3], plane[3:]
        norm = math.sqrt(sum(c * c for c in n))
        self.normal = [c / norm for c in n]
        self.radius = radius
        self.order = order
        self.cmd = [0] * 20
        self.ring = [0] * (SLOTS * SLOT)
        self.pos = [0.0, 0.0, 350.0, 0.0, 0.0, 0.0]
        self.status_seq = self.acked = self.done = self.result = 0
        self.latch_count = 0
        self.seen = 0
        self.time_us = 0
        self.motion = None  # (kind, target, feed mm/s, max_steps)
        self.armed = False
        self.spindle = spindle
        self.spindle_millideg = 0

    def reset(self):
        pass

    def gap(self, p):
        return sum((p[i] - self.point[i]) * self.normal[i] for i in range(3)) - self.radius

    def getValues(self, func_code, address, count=1):
        blocks = [(CMD, self.cmd), (STATUS, self.status()), (RING, self.ring)]
        for base, regs in blocks:
            if base <= address and address + count <= base + len(regs):
                return regs[address - base:address - base + count]
        return ExcCodes.ILLEGAL_ADDRESS

    def setValues(self, func_code, address, values):
        if not (CMD <= address and address + len(values) <= CMD + 20):
            return ExcCodes.ILLEGAL_ADDRESS
        self.cmd[address - CMD:address - CMD + len(values)] = values
        return None

    def status(self):
        bits = READY | (BUSY if self.motion else IN_POSITION)
        if self.gap(self.pos) <= 0:
            bits |= DEFLECTED
        if self.armed:
            bits |= ARMED
        regs = [self.status_seq, self.acked, self.done, bits, self.result, 0,
                self.latch_count, self.cmd[17]]
        for v in self.pos:
            regs += put32(self.order, round(v * COUNTS))
        regs += put32(self.order, self.time_us)
        return regs

    def finish(self, result):
        self.result = result
        self.done = self.acked
        self.motion = None
        self.armed = False

    def take_command(self):
        seq = self.cmd[19]
        if seq == self.seen:
            return
        self.seen = self.acked = seq
        code, mask = self.cmd[0], self.cmd[1]
        feed = (get32(self.order, self.cmd[2:4]) & 0xFFFFFFFF) / 1000.0 / 60.0
        target = list(self.pos)
        for i in range(6):
            if mask & (1 << i):
                target[i] = get32(self.order, self.cmd[4 + 2 * i:6 + 2 * i]) / COUNTS
        if code == 5:
            angle = get32(self.order, self.cmd[4:6])
            if not self.spindle or not 0 <= angle < 360000:
                self.finish(REJECTED)
            elif self.gap(self.pos) <= 0:
                self.finish(ALREADY_DEFLECTED)
            else:
                self.spindle_millideg = angle
                print(f"orient {angle}", flush=True)
                self.finish(OK)
            return
        if code == 1:
            self.motion = ("move", target, feed)
        elif code == 2:
            if self.gap(self.pos) <= 0:
                self.finish(ALREADY_DEFLECTED)
                return
            self.armed = self.cmd[17] == self.latch_count
            self.motion = ("probe", target, feed)
        else:
            self.finish(OK)

    def latch(self, p):
        n = (self.latch_count + 1) & 0xFFFF
        slot = [n, self.acked, 0b101111]
        for v in p:
            slot += put32(self.order, round(v * COUNTS))
        slot += put32(self.order, self.time_us)
        slot += [n]
        at = (n % SLOTS) * SLOT
        self.ring[at:at + SLOT] = slot
        self.latch_count = n

    def cycle(self):
        self.time_us = (self.time_us + 1000) & 0xFFFFFFFF
        self.status_seq = (self.status_seq + 1) & 0xFFFF
        self.take_command()
        if not self.motion:
            return
        kind, target, feed = self.motion
        delta = [target[i] - self.pos[i] for i in range(6)]
        lin = math.sqrt(sum(d * d for d in delta[:3]))
        length = lin if lin > 1e-9 else math.sqrt(sum(d * d for d in delta[3:]))
        step = feed * CYCLE_S * SPEEDUP
        f = 1.0 if length <= step else step / length
        nxt = [self.pos[i] + f * delta[i] for i in range(6)]
        g0, g1 = self.gap(self.pos), self.gap(nxt)
        if g0 > 0 >= g1:
            t = g0 / (g0 - g1)
            edge = [self.pos[i] + t * (nxt[i] - self.pos[i]) for i in range(6)]
            if kind == "probe" and self.armed:
                self.latch(edge)
                self.pos = edge
                self.finish(CONTACT)
                return
            if kind == "move":
                self.pos = edge
                self.finish(COLLISION)
                return
        self.pos = nxt
        if f >= 1.0:
            self.finish(NOT_TRIGGERED if kind == "probe" else OK)


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plane", required=True)
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--word-order", default="ABCD", choices=["ABCD", "CDAB", "BADC", "DCBA"])
    ap.add_argument("--spindle", action="store_true")
    args = ap.parse_args()
    plc = Plc([float(v) for v in args.plane.split(",")], args.radius, args.word_order,
              args.spindle)
    server = ModbusTcpServer(ModbusServerContext(devices=plc, single=True), address=("127.0.0.1", 0))
    await server.serve_forever(background=True)
    port = server.transport.sockets[0].getsockname()[1]
    print(f"modbus tcp 127.0.0.1:{port}", flush=True)
    while True:
        plc.cycle()
        await asyncio.sleep(CYCLE_S)


if __name__ == "__main__":
    asyncio.run(main())
