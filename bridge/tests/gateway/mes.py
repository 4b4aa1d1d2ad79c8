"""A factory MES playing against `probebridge serve`'s OPC UA face, with Python's
asyncua, written from the gateway page's address-space table. Usage:

    mes.py URL MACHINE CERTDIR SERVER_CERT COMMAND [ARGS]

CERTDIR holds the MES's own certificate (made on first use); SERVER_CERT is the
gateway's (from its state directory). Prints one JSON object on stdout; exits 1 with
the failed check on stderr."""

import asyncio
import json
import sys
import time
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from asyncua.ua.ua_binary import struct_from_binary
from cryptography.x509.oid import ExtendedKeyUsageOID

NS_URI = "urn:probebridge:machine"
# The companion specifications' namespaces, by the prefixes the paths below use; a
# path's part without a prefix is of the gateway's namespace.
PREFIXES = {"0": "http://opcfoundation.org/UA/", "DI": "http://opcfoundation.org/UA/DI/",
            "M": "http://opcfoundation.org/UA/Machinery/",
            "MT": "http://opcfoundation.org/UA/MachineTool/"}
APP_URI = "urn:probebridge:test:mes"
TIMEOUT = 180.0
USER, PASSWORD = "mes", "measure 431!"
PARAMS = [1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1000.125]


def check(cond, what):
    if not cond:
        print(f"FAILED: {what}", file=sys.stderr)
        sys.exit(1)


class Mes:
    def __init__(self, url, machine, certdir, server_cert):
        self.url, self.machine = url, machine
        self.certdir, self.server_cert = Path(certdir), server_cert

    async def client(self, user=None, password=None, secure=True):
        c = Client(self.url, timeout=20)
        c.application_uri = APP_URI
        if secure:
            key, cert = self.certdir / "mes-key.pem", self.certdir / "mes-cert.der"
            await setup_self_signed_certificate(
                key, cert, APP_URI, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
                {"commonName": "probebridge test MES"},
            )
            await c.set_security(
                SecurityPolicyBasic256Sha256, str(cert), str(key),
                server_certificate=self.server_cert,
                mode=ua.MessageSecurityMode.SignAndEncrypt,
            )
        if user is not None:
            c.set_user(user)
            c.set_password(password)
        return c

    async def machine_node(self, c):
        """Objects/Machinery's Machines/the machine; `ns` maps a path's prefixes to
        the server's namespace indexes."""
        array = await c.get_namespace_array()
        ns = {k: array.index(uri) for k, uri in PREFIXES.items()}
        ns[""] = array.index(NS_URI)
        node = await c.nodes.root.get_child(
            ["0:Objects", f"{ns['M']}:Machines", f"{ns['']}:{self.machine}"])
        return ns, node

    @staticmethod
    async def child(node, ns, path):
        """`path`: browse names joined by /, each `PREFIX:Name` or `Name` (the
        gateway's namespace)."""
        parts = []
        for p in path.split("/"):
            prefix, _, name = p.rpartition(":")
            parts.append(f"{ns[prefix]}:{name}")
        return await node.get_child(parts)


def plain(v):
    return v.Text if isinstance(v, ua.LocalizedText) else v


async def read_values(mes, c, ns, machine, paths):
    out = {}
    for p in paths:
        out[p] = plain(await (await mes.child(machine, ns, p)).read_value())
    return out


async def browse(mes):
    """Anonymous, without security: browse by browse names, read identification and
    state."""
    c = await mes.client(secure=False)
    async with c:
        ns, machine = await mes.machine_node(c)
        names = sorted([(await n.read_browse_name()).Name for n in await machine.get_children()])
        values = await read_values(mes, c, ns, machine, [
            "DI:Identification/DI:Manufacturer", "DI:Identification/DI:Model",
            "DI:Identification/DI:SerialNumber", "DI:Identification/DI:SoftwareRevision",
            "DI:Identification/DI:ProductInstanceUri",
            "MT:Monitoring/MT:MachineTool/M:MachineryItemState/0:CurrentState",
            "MT:Monitoring/MachineOk", "MT:Monitoring/Bus", "MT:Monitoring/RunState",
        ])
        methods = sorted([(await n.read_browse_name()).Name
                          for n in await (await mes.child(machine, ns, "MT:Production")).get_methods()])
        # Anonymous clients read only (every variable is read-only).
        try:
            await (await mes.child(machine, ns, "MT:Monitoring/RunState")).write_value(
                ua.Variant("busy", ua.VariantType.String))
            write = "written"
        except ua.UaStatusCodeError as e:
            write = type(e).__name__
        return {"children": names, "values": values, "methods": methods,
                "anonymous_write": write}


class Changes:
    """Subscription handler: each value with the client's receive time and the
    server's timestamp."""

    def __init__(self):
        self.seen = {}
        self.event = asyncio.Event()

    def datachange_notification(self, node, val, data):
        now = time.time()
        dv = data.monitored_item.Value
        stamp = dv.SourceTimestamp or dv.ServerTimestamp
        latency = (now - stamp.timestamp()) * 1000.0 if stamp else None
        self.seen.setdefault(str(node.nodeid.Identifier), []).append((val, latency))
        self.event.set()

    def values(self, ident, since=None):
        return [v for v, _ in self.seen.get(ident, [])[(since or {}).get(ident, 0):]]

    def mark(self):
        """Where each item's values stand now: `since` for values() and wait_for(),
        so that a wait is not answered by a value from before (a subscription's first
        notification is the last run's)."""
        return {k: len(v) for k, v in self.seen.items()}

    async def wait_for(self, ident, pred, since=None):
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            if any(pred(v) for v in self.values(ident, since)):
                return
            self.event.clear()
            try:
                await asyncio.wait_for(self.event.wait(), 1.0)
            except asyncio.TimeoutError:
                pass
        check(False, f"timed out waiting for {ident}: {self.values(ident)}")


async def call(c, production, name, *args):
    ns = production.nodeid.NamespaceIndex
    method = await production.get_child([f"{ns}:{name}"])
    return await production.call_method(method, *args)


async def run_program(mes, program, cycle):
    """As the user, over Basic256Sha256 SignAndEncrypt: subscribe, start the program,
    see it run to done; the results of `cycle` by name and the last run of the
    history."""
    c = await mes.client(USER, PASSWORD)
    async with c:
        ns, machine = await mes.machine_node(c)
        watched = ["MT:Monitoring/RunState", "MT:Monitoring/ProgressPermille",
                   "MT:Production/MT:ActiveProgram/MT:State/0:CurrentState", f"Measurements/Cycle{cycle}/ResultValues"]
        nodes = [await mes.child(machine, ns, p) for p in watched]
        changes = Changes()
        sub = await c.create_subscription(10, changes)
        await sub.subscribe_data_change(nodes, queuesize=10)
        await changes.wait_for("Machine.Monitoring.RunState", lambda v: v is not None)
        production = await mes.child(machine, ns, "MT:Production")
        params = ua.Variant(PARAMS, ua.VariantType.Float)
        reason, text = await call(c, production, "StartProgram",
                                  ua.Variant(program, ua.VariantType.UInt16), params, True)
        check(reason == 0, f"StartProgram taken: {reason} {text}")
        # The state before is the PLC's run's "done": wait for busy, then its end.
        await changes.wait_for("Machine.Monitoring.RunState", lambda v: v == "busy")
        ident = "Machine.Monitoring.RunState"
        deadline = time.monotonic() + TIMEOUT
        while True:
            states = changes.values(ident)
            after = states[states.index("busy") + 1:]
            if any(v in ("done", "error", "aborted") for v in after):
                break
            check(time.monotonic() < deadline, f"the run's end: {states}")
            await asyncio.sleep(0.01)
        check(states[-1] == "done", f"{program} done: {states}")
        await changes.wait_for(f"Machine.Measurements.Cycle{cycle}.ResultValues", lambda v: v)
        results = {}
        for n in await (await mes.child(machine, ns, f"Measurements/Cycle{cycle}")).get_children():
            name = (await n.read_browse_name()).Name
            if name not in ("Time", "ResultNames", "ResultValues"):
                results[name] = await n.read_value()
        # The last runs are read from the history once the run has ended: wait for it.
        run = await mes.child(machine, ns, "Measurements/LastRuns/Run01")
        source, status = [await mes.child(run, ns, p) for p in ("Source", "Status")]
        deadline = time.monotonic() + 30
        while (await source.read_value(), await status.read_value()) != ("opcua", "done"):
            check(time.monotonic() < deadline, "Run01 is the MES's run, done")
            await asyncio.sleep(0.02)
        run01 = {(await n.read_browse_name()).Name: await n.read_value()
                 for n in await run.get_children()}
        for k in ("Started", "Finished"):
            run01[k] = str(run01[k])
        active = await read_values(mes, c, ns, machine, [
            "MT:Production/MT:ActiveProgram/Number", "MT:Production/MT:ActiveProgram/MT:State/0:CurrentState",
            "MT:Production/MT:ActiveProgram/StartedBy", "MT:Production/MT:ActiveProgram/StartTime",
            "MT:Production/MT:ActiveProgram/EndTime"])
        for k in ("StartTime", "EndTime"):
            t = active[f"MT:Production/MT:ActiveProgram/{k}"]
            active[f"MT:Production/MT:ActiveProgram/{k}"] = t.timestamp() if t else None
        latencies = [lat for vals in changes.seen.values() for _, lat in vals[1:] if lat is not None]
        await sub.delete()
        return {"states": states, "results": results, "run01": run01, "active": active,
                "latencies_ms": latencies}


async def refusals(mes, program):
    """StartProgram anonymously (over the secured endpoint) is refused; a wrong
    password does not even log in."""
    out = {}
    c = await mes.client()
    async with c:
        ns, machine = await mes.machine_node(c)
        production = await mes.child(machine, ns, "MT:Production")
        try:
            await call(c, production, "StartProgram", ua.Variant(program, ua.VariantType.UInt16),
                       ua.Variant([0.0] * 8, ua.VariantType.Float), False)
            out["anonymous"] = "taken"
        except ua.UaStatusCodeError as e:
            out["anonymous"] = type(e).__name__
        out["state"] = await (await mes.child(machine, ns, "MT:Monitoring/RunState")).read_value()
    c = await mes.client(USER, "not the password")
    try:
        await c.connect()
        out["wrong_password"] = "logged in"
        await c.disconnect()
    except Exception as e:  # the server refuses the session's activation
        out["wrong_password"] = type(e).__name__
    return out


async def start_while_plc_runs(mes, program):
    """The PLC runs one: StartProgram is refused as busy (reason 1); Abort ends the
    PLC's run (the same abort flag)."""
    c = await mes.client(USER, PASSWORD)
    async with c:
        ns, machine = await mes.machine_node(c)
        production = await mes.child(machine, ns, "MT:Production")
        state = await (await mes.child(machine, ns, "MT:Monitoring/RunState")).read_value()
        started_by = await (await mes.child(machine, ns, "MT:Production/MT:ActiveProgram/StartedBy")).read_value()
        refused = await call(c, production, "StartProgram", ua.Variant(program, ua.VariantType.UInt16),
                             ua.Variant([0.0] * 8, ua.VariantType.Float), True)
        aborted = await call(c, production, "Abort")
        changes = Changes()
        sub = await c.create_subscription(10, changes)
        await sub.subscribe_data_change([await mes.child(machine, ns, "MT:Monitoring/RunState")])
        await changes.wait_for("Machine.Monitoring.RunState", lambda v: v != "busy")
        after = await read_values(mes, c, ns, machine, [
            "MT:Monitoring/RunState", "MT:Monitoring/ErrorKind", "MT:Production/MT:ActiveProgram/MT:State/0:CurrentState"])
        again = await call(c, production, "Abort")
        return {"state": state, "started_by": started_by, "refused": refused, "abort": aborted,
                "after": after, "abort_again": again}


async def start(mes, program):
    """As the user: StartProgram once; its answer and how long it took (ms)."""
    c = await mes.client(USER, PASSWORD)
    async with c:
        ns, machine = await mes.machine_node(c)
        production = await mes.child(machine, ns, "MT:Production")
        t = time.monotonic()
        answer = await call(c, production, "StartProgram", ua.Variant(program, ua.VariantType.UInt16),
                            ua.Variant([0.0] * 8, ua.VariantType.Float), True)
        return {"answer": answer, "ms": round((time.monotonic() - t) * 1000, 1)}


async def start_abort(mes, program):
    """As the user: StartProgram, then Abort once it has probed a point: the run ends
    aborted (error kind 20)."""
    c = await mes.client(USER, PASSWORD)
    async with c:
        ns, machine = await mes.machine_node(c)
        production = await mes.child(machine, ns, "MT:Production")
        changes = Changes()
        sub = await c.create_subscription(10, changes)
        state, point = "Machine.Monitoring.RunState", "Machine.Monitoring.Point"
        await sub.subscribe_data_change([await mes.child(machine, ns, p)
                                         for p in ("MT:Monitoring/RunState", "MT:Monitoring/Point")])
        # The first notifications are the last run's (the PLC's aborted 451, its
        # points): only what comes after them is this run's.
        await changes.wait_for(state, lambda v: v is not None)
        await changes.wait_for(point, lambda v: True)
        before = changes.mark()
        started = await call(c, production, "StartProgram", ua.Variant(program, ua.VariantType.UInt16),
                             ua.Variant([0.0] * 8, ua.VariantType.Float), True)
        check(started[0] == 0, f"started: {started}")
        await changes.wait_for(state, lambda v: v == "busy", before)
        await changes.wait_for(point, lambda v: v is not None and v >= 1, before)
        aborted = await call(c, production, "Abort")
        await changes.wait_for(state, lambda v: v in ("aborted", "done", "error"), before)
        after = await read_values(mes, c, ns, machine, [
            "MT:Monitoring/RunState", "MT:Monitoring/ErrorKind", "MT:Monitoring/Point",
            "MT:Production/MT:ActiveProgram/MT:State/0:CurrentState", "MT:Production/MT:ActiveProgram/StartedBy"])
        acknowledged = await call(c, production, "Acknowledge")
        await changes.wait_for(state, lambda v: v == "idle", before)
        error_kind = await (await mes.child(machine, ns, "MT:Monitoring/ErrorKind")).read_value()
        return {"started": started, "abort": aborted, "after": after,
                "acknowledge": acknowledged, "error_kind_after_ack": error_kind,
                "states": changes.values(state, before)}


async def stalled(mes, queued):
    """A subscriber that never publishes: the server keeps at most `queued`
    notifications of its subscription, whatever happened meanwhile."""
    c = await mes.client(secure=False)
    async with c:
        ns, machine = await mes.machine_node(c)
        hb = await mes.child(machine, ns, "MT:Monitoring/Heartbeat")
        params = ua.CreateSubscriptionParameters(
            RequestedPublishingInterval=10, RequestedLifetimeCount=30000,
            RequestedMaxKeepAliveCount=1000, MaxNotificationsPerPublish=0,
            PublishingEnabled=True, Priority=0)
        # Not Client.create_subscription: that starts asyncua's publish loop.
        req = ua.CreateSubscriptionRequest(Parameters=params)
        data = await c.uaclient.session._send_request(req)
        sub = struct_from_binary(ua.CreateSubscriptionResponse, data)
        sub.ResponseHeader.ServiceResult.check()
        sid = sub.Parameters.SubscriptionId
        item = ua.MonitoredItemCreateRequest(
            ItemToMonitor=ua.ReadValueId(NodeId=hb.nodeid, AttributeId=ua.AttributeIds.Value),
            MonitoringMode=ua.MonitoringMode.Reporting,
            RequestedParameters=ua.MonitoringParameters(
                ClientHandle=1, SamplingInterval=0, QueueSize=1, DiscardOldest=True))
        res = await c.uaclient.create_monitored_items(ua.CreateMonitoredItemsParameters(
            SubscriptionId=sid, TimestampsToReturn=ua.TimestampsToReturn.Both,
            ItemsToCreate=[item]))
        res[0].StatusCode.check()
        # The heartbeat changes every 50 ms: wait for far more changes than kept.
        first = await hb.read_value()
        deadline = time.monotonic() + 30
        while (await hb.read_value() - first) % 65536 < 4 * queued and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        changed = (await hb.read_value() - first) % 65536
        messages, seqs, values = 0, [], 0
        while True:
            pub = await c.uaclient.publish([])
            msg = pub.Parameters.NotificationMessage
            if not msg.NotificationData:
                break
            messages += 1
            seqs.append(msg.SequenceNumber)
            for d in msg.NotificationData:
                values += len(getattr(d, "MonitoredItems", []) or [])
            if not pub.Parameters.MoreNotifications:
                break
        return {"heartbeat_changes": changed, "messages": messages, "values": values,
                "sequence_numbers": seqs}


async def call_and_types(mes):
    """As the user (over SignAndEncrypt): how long connecting took, Acknowledge's
    answer, StartProgram with an Int32 where UInt16 is declared, and the discovery
    URLs of FindServers."""
    t0 = time.monotonic()
    c = await mes.client(USER, PASSWORD)
    async with c:
        out = {"connect_s": time.monotonic() - t0}
        ns, machine = await mes.machine_node(c)
        production = await mes.child(machine, ns, "MT:Production")
        out["acknowledge"] = await call(c, production, "Acknowledge")
        try:
            await call(c, production, "StartProgram", ua.Variant(431, ua.VariantType.Int32))
            out["int32"] = "taken"
        except ua.UaStatusCodeError as e:
            out["int32"] = type(e).__name__
        servers = await c.find_servers()
        out["discovery_urls"] = [u for s in servers for u in (s.DiscoveryUrls or [])]
    return out


async def guesses(mes, n):
    """n logins with a wrong password, then one with the right one: how long each took
    to be answered, and whether the last logged in."""
    out = {"wrong_s": []}
    start = time.monotonic()
    for _ in range(n):
        c = await mes.client(USER, "a guess")
        t0 = time.monotonic()
        try:
            await c.connect()
            await c.disconnect()
            check(False, "a wrong password logged in")
        except Exception:
            pass
        out["wrong_s"].append(time.monotonic() - t0)
    c = await mes.client(USER, PASSWORD)
    t0 = time.monotonic()
    async with c:
        out["right_s"] = time.monotonic() - t0
    out["total_s"] = time.monotonic() - start
    return out


async def main():
    url, machine, certdir, server_cert, cmd = sys.argv[1:6]
    args = sys.argv[6:]
    mes = Mes(url, machine, certdir, server_cert)
    if cmd == "browse":
        out = await browse(mes)
    elif cmd == "run":
        # run PROGRAM [CYCLE]: the cycle whose results to read (default: the number).
        out = await run_program(mes, int(args[0]), int(args[-1]))
    elif cmd == "refusals":
        out = await refusals(mes, int(args[0]))
    elif cmd == "while_plc_runs":
        out = await start_while_plc_runs(mes, int(args[0]))
    elif cmd == "start":
        out = await start(mes, int(args[0]))
    elif cmd == "start_abort":
        out = await start_abort(mes, int(args[0]))
    elif cmd == "stalled":
        out = await stalled(mes, int(args[0]))
    elif cmd == "guesses":
        out = await guesses(mes, int(args[0]))
    elif cmd == "call":
        out = await call_and_types(mes)
    elif cmd == "connect":
        c = await mes.client(USER, PASSWORD)
        try:
            await c.connect()
            await c.disconnect()
            out = {"connected": True}
        except Exception as e:
            out = {"connected": False, "error": f"{type(e).__name__}: {e}"}
    else:
        check(False, f"unknown command {cmd}")
    print(json.dumps(out, default=str))


if __name__ == "__main__":
    asyncio.run(main())
