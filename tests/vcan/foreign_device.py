#!/usr/bin/env python3
"""A CiA 402 drive that is not ours: python-canopen's LocalNode serving an EDS, for
our master's SDO start-up configuration (tests/vcan/foreign_master.rs) on IFACE.

Usage: foreign_device.py --iface vcan0 --eds tests/vcan/cia402-drive.eds --node 1
       --name NAME --ready FILE

It serves until SIGTERM, then prints one line per check `CHECK <name>: <observed> ->
ok|FAIL` and exits with the number of failed checks. Its own view: every SDO download
it received (seen on the bus as the request frames) is in its object dictionary as
written, byte for byte.
"""

import argparse
import logging
import signal
import sys
import threading

import canopen

failures = []


def check(name, ok, observed):
    print(f"CHECK {name}: {observed} -> {'ok' if ok else 'FAIL'}", flush=True)
    if not ok:
        failures.append(name)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iface", default="vcan0")
    ap.add_argument("--eds", required=True)
    ap.add_argument("--node", type=int, default=1)
    ap.add_argument("--name", required=True, help="0x1008, longer than 4 bytes: segmented")
    ap.add_argument("--ready", required=True, help="file written once the node listens")
    args = ap.parse_args()
    logging.getLogger("canopen").setLevel(logging.ERROR)

    network = canopen.Network()
    network.connect(interface="socketcan", channel=args.iface)
    node = canopen.LocalNode(args.node, args.eds)
    network.add_node(node)
    # Its own identity, not the EDS default: the master must read what the device says.
    node.data_store[0x1008] = {0: args.name.encode("ascii")}

    # python-canopen's LocalNode takes an NMT reset but sends no boot-up: a device's
    # firmware does (CiA 301: boot-up, then pre-operational).
    def on_nmt(_can_id, data, _timestamp):
        cmd, target = data[0], data[1]
        if target in (0, args.node) and cmd in (0x81, 0x82):
            node.nmt.send_command(cmd)
            node.nmt.send_command(0x80)

    network.subscribe(0, on_nmt)

    # Every expedited download request (initiate, e = 1), in order, from the bus.
    downloads = []
    aborts_sent = []

    def on_request(_can_id, data, _timestamp):
        if len(data) == 8 and data[0] & 0xE2 == 0x22:
            n = 4 - ((data[0] >> 2) & 3) if data[0] & 1 else 4
            downloads.append((data[1] | data[2] << 8, data[3], bytes(data[4 : 4 + n])))

    # Its own answers do not come back from the bus: the aborts as the server sends them.
    send_response = node.sdo.send_response

    def sending(data):
        if len(data) == 8 and data[0] == 0x80:
            aborts_sent.append((data[1] | data[2] << 8, data[3], int.from_bytes(data[4:8], "little")))
        send_response(data)

    node.sdo.send_response = sending
    network.subscribe(0x600 + args.node, on_request)
    with open(args.ready, "w") as f:
        f.write("listening\n")

    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    done.wait()

    # The last value written per object must be what the dictionary holds. (Writes the
    # device refused are not stored; the master reports those it provoked.)
    refused = {(i, s) for i, s, _ in aborts_sent}
    last = {}
    for index, sub, data in downloads:
        if (index, sub) not in refused:
            last[(index, sub)] = data
    wrong = []
    for (index, sub), data in sorted(last.items()):
        stored = node.data_store.get(index, {}).get(sub)
        if stored != data:
            wrong.append(f"{index:04X}:{sub:02X} written {data.hex()} holds {stored.hex() if stored else None}")
    check("foreign_device_downloads_as_written", len(last) >= 20 and not wrong,
          f"{len(downloads)} expedited downloads to {len(last)} objects; "
          + ("all held as written" if not wrong else "; ".join(wrong)))
    counts = [node.data_store.get(i, {}).get(0, b"\x00")[0] for i in (0x1600, 0x1601, 0x1A00, 0x1A01)]
    check("foreign_device_pdo_mapping", counts == [2, 1, 2, 2],
          f"mapping counts RPDO1 RPDO2 TPDO1 TPDO2 = {counts}")
    check("foreign_device_nmt_state", node.nmt.state == "OPERATIONAL",
          f"NMT state after the master's start-up: {node.nmt.state}")
    aborts = ", ".join(f"{i:04X}:{s:02X} 0x{c:08X}" for i, s, c in aborts_sent)
    print(f"foreign device: aborts sent: {aborts or 'none'}", flush=True)
    network.disconnect()
    print(f"foreign device: {len(failures)} failed: {' '.join(failures) or '-'}", flush=True)
    return min(len(failures), 100)


if __name__ == "__main__":
    sys.exit(main())
