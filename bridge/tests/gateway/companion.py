"""The OPC UA face against the companion specifications, with Python's asyncua and the
OPC Foundation's NodeSet2 files (no code of the gateway's). Usage:

    companion.py URL NODESET_DIR

Anonymous, over the `none` endpoint. Loads the server's data type definitions (as a
type-aware client does: MachineOperationMode must come out as its enumeration). Finds
the machines under Machinery's Machines
folder by their type definition (MachineToolType or a subtype, by namespace URI and
id, not by browse name), then walks each machine's tree against the type definitions:
every component a type marks Mandatory (its supertypes' and interfaces' included, and
the nested declarations of an instance declaration) is there with the declared browse
name (namespace included), node class, type definition (or a subtype) and data type
(or a subtype). The declarations of the companion types come from the NodeSet2 files;
those of the base namespace and the gateway's own types from the server, and the
server's copies of the companion types are compared with the files'.

Prints one JSON object: the namespace array, the machines found, the checks made, the
failures (none when it conforms) and every node below each machine (path, node class,
type definition, data type) for the docs' table."""

import asyncio
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from asyncua import Client, ua

BASE = "http://opcfoundation.org/UA/"
DI = "http://opcfoundation.org/UA/DI/"
MACHINERY = "http://opcfoundation.org/UA/Machinery/"
MACHINE_TOOL = "http://opcfoundation.org/UA/MachineTool/"
COMPANIONS = [DI, "http://opcfoundation.org/UA/IA/", MACHINERY,
              "http://opcfoundation.org/UA/Machinery/Jobs/",
              "http://opcfoundation.org/UA/ISA95-JOBCONTROL_V2/", MACHINE_TOOL]
OWN = "urn:probebridge:machine"
PREFIX = {BASE: "", DI: "DI:", MACHINERY: "Machinery:", MACHINE_TOOL: "MachineTool:",
          OWN: "PB:"}
NSX = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
# Hierarchical references an instance's children hang by; HasInterface (17603) is
# followed for types only.
HIERARCHICAL = {35, 46, 47, 49, 17604}
HAS_SUBTYPE, HAS_TYPE_DEFINITION, HAS_MODELLING_RULE, HAS_INTERFACE = 45, 40, 37, 17603
MANDATORY = (BASE, 78)
BASE_OBJECT_TYPE, BASE_VARIABLE_TYPE = (BASE, 58), (BASE, 62)


class Nodeset:
    """The NodeSet2 files: nodes by (uri, numeric id)."""

    def __init__(self, folder):
        self.nodes, self.children_of = {}, {}
        for f in sorted(Path(folder).glob("*.xml")):
            root = ET.parse(f).getroot()
            uris = [BASE] + [u.text for u in root.find(NSX + "NamespaceUris")]
            al = root.find(NSX + "Aliases")
            aliases = {a.get("Alias"): a.text for a in al} if al is not None else {}

            def nid(s, uris=uris, aliases=aliases):
                s = aliases.get(s, s)
                ns, rest = (s.split(";", 1) if s.startswith("ns=") else ("ns=0", s))
                assert rest.startswith("i="), s
                return (uris[int(ns[3:])], int(rest[2:]))

            def qn(s, uris=uris):
                head, _, name = s.partition(":")
                return (uris[int(head)], name) if name and head.isdigit() else (BASE, s)

            for e in root:
                tag = e.tag[len(NSX):]
                if not tag.startswith("UA"):
                    continue
                refs = []
                r = e.find(NSX + "References")
                for x in (r if r is not None else []):
                    refs.append((nid(x.get("ReferenceType"))[1] if nid(x.get("ReferenceType"))[0] == BASE
                                 else None, x.get("IsForward", "true") != "false", nid(x.text.strip())))
                self.nodes[nid(e.get("NodeId"))] = {
                    "class": tag[2:], "browse": qn(e.get("BrowseName")),
                    "data_type": nid(e.get("DataType")) if e.get("DataType") else None,
                    "refs": refs}
        for n, v in self.nodes.items():
            for ref, fwd, target in v["refs"]:
                if ref in HIERARCHICAL or ref == HAS_INTERFACE:
                    parent, child = (n, target) if fwd else (target, n)
                    self.children_of.setdefault(parent, set()).add((ref, child))

    def ref(self, node, ref_type):
        return [t for r, fwd, t in self.nodes[node]["refs"] if r == ref_type and fwd]


class Server:
    def __init__(self, client, uris):
        self.c, self.uris = client, uris
        self.cache = {}

    def node_id(self, key):
        return ua.NodeId(key[1], self.uris.index(key[0]))

    def key(self, node_id):
        return (self.uris[node_id.NamespaceIndex], node_id.Identifier)

    async def refs(self, node_id, ref_type, forward=True, subtypes=True):
        k = (node_id.to_string(), ref_type, forward)
        if k not in self.cache:
            d = ua.BrowseDirection.Forward if forward else ua.BrowseDirection.Inverse
            self.cache[k] = await self.c.get_node(node_id).get_references(
                refs=ref_type, direction=d, includesubtypes=subtypes)
        return self.cache[k]

    async def supertypes(self, node_id):
        """The type and its supertypes, most derived first."""
        chain = [node_id]
        while True:
            up = await self.refs(chain[-1], HAS_SUBTYPE, forward=False, subtypes=False)
            if not up:
                return chain
            chain.append(up[0].NodeId)

    async def is_subtype(self, node_id, of):
        return of in await self.supertypes(node_id)


def qname(server, bn):
    return (server.uris[bn.NamespaceIndex], bn.Name)


def show(bn):
    return PREFIX.get(bn[0], bn[0] + ":") + bn[1]


class Check:
    def __init__(self, server, nodeset):
        self.s, self.x = server, nodeset
        self.failures, self.checked = [], 0

    def fail(self, path, what):
        self.failures.append(f"{path}: {what}")

    async def declarations(self, type_key, seen=None):
        """Mandatory instance declarations of a type, its supertypes and interfaces:
        browse name -> declaration (source, id)."""
        out = {}
        chain = await self.s.supertypes(self.s.node_id(type_key))
        for t in chain:
            tk = self.s.key(t)
            for bn, d in (await self.own_declarations(tk)).items():
                out.setdefault(bn, d)
            for i in await self.interfaces(tk):
                for bn, d in (await self.declarations(i)).items():
                    out.setdefault(bn, d)
        return out

    async def interfaces(self, key):
        if key[0] in COMPANIONS:
            return [t for r, t in self.x.children_of.get(key, ()) if r == HAS_INTERFACE]
        refs = await self.s.refs(self.s.node_id(key), HAS_INTERFACE)
        return [self.s.key(r.NodeId) for r in refs]

    async def own_declarations(self, key):
        """The mandatory children declared directly below a type or a declaration."""
        out = {}
        if key[0] in COMPANIONS:
            for ref, child in self.x.children_of.get(key, ()):
                if ref == HAS_INTERFACE or child not in self.x.nodes:
                    continue
                if MANDATORY in self.x.ref(child, HAS_MODELLING_RULE):
                    n = self.x.nodes[child]
                    td = self.x.ref(child, HAS_TYPE_DEFINITION)
                    out[n["browse"]] = {"key": child, "class": n["class"],
                                        "type": td[0] if td else None,
                                        "data_type": n["data_type"]}
            return out
        for r in await self.s.refs(self.s.node_id(key), 33):
            if r.ReferenceTypeId == ua.NodeId(HAS_INTERFACE):
                continue
            rules = await self.s.refs(r.NodeId, HAS_MODELLING_RULE)
            if not any(x.NodeId == ua.NodeId(78) for x in rules):
                continue
            d = {"key": self.s.key(r.NodeId), "class": r.NodeClass.name,
                 "type": self.s.key(r.TypeDefinition) if r.TypeDefinition.Identifier else None,
                 "data_type": None}
            if r.NodeClass == ua.NodeClass.Variable:
                d["data_type"] = self.s.key(
                    await self.s.c.get_node(r.NodeId).read_data_type())
            out[qname(self.s, r.BrowseName)] = d
        return out

    async def same_as_files(self, type_key):
        """The server's copy of a companion type declares what its file declares."""
        files = await self.own_declarations(type_key)
        server = {}
        for r in await self.s.refs(self.s.node_id(type_key), 33):
            rules = await self.s.refs(r.NodeId, HAS_MODELLING_RULE)
            if any(x.NodeId == ua.NodeId(78) for x in rules):
                server[qname(self.s, r.BrowseName)] = self.s.key(r.NodeId)
        want = {bn: d["key"] for bn, d in files.items()}
        if want != server:
            self.fail(show(type_key_name(self.x, type_key)),
                      f"the server's mandatory declarations {sorted(server)} are not the "
                      f"NodeSet's {sorted(want)}")

    async def instance(self, node_id, path, declared, depth=0):
        """Checks the children of an instance against `declared` (browse name ->
        declaration); recurses into each declared child."""
        children = {}
        for r in await self.s.refs(node_id, 33):
            children.setdefault(qname(self.s, r.BrowseName), r)
        for bn, d in sorted(declared.items()):
            where = f"{path}/{show(bn)}"
            self.checked += 1
            r = children.get(bn)
            if r is None:
                self.fail(where, "missing (Mandatory)")
                continue
            if r.NodeClass.name != d["class"]:
                self.fail(where, f"a {r.NodeClass.name}, declared a {d['class']}")
            if d["type"]:
                td = r.TypeDefinition
                if td.Identifier in (None, 0) or not await self.s.is_subtype(
                        td, self.s.node_id(d["type"])):
                    self.fail(where, f"type definition {td.to_string()}, declared "
                              f"{d['type']} or a subtype")
            if d["data_type"]:
                dt = await self.s.c.get_node(r.NodeId).read_data_type()
                if not await self.s.is_subtype(dt, self.s.node_id(d["data_type"])):
                    self.fail(where, f"data type {dt.to_string()}, declared {d['data_type']}")
            nested = dict(await self.own_declarations(d["key"]))
            if d["type"]:
                for k, v in (await self.declarations(d["type"])).items():
                    nested.setdefault(k, v)
            if depth < 8:
                await self.instance(r.NodeId, where, nested, depth + 1)


def type_key_name(nodeset, key):
    return nodeset.nodes[key]["browse"] if key in nodeset.nodes else key


def plain(v):
    """A value as JSON can hold it."""
    if isinstance(v, ua.LocalizedText):
        return v.Text
    if isinstance(v, ua.NodeId):
        return v.to_string()
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return str(v)


async def tree(server, node_id, path, out, above):
    """Every node below `node_id` by hierarchical references, on each path it is
    reached by (a node in two places, e.g. an AddIn of MachineryBuildingBlocks, twice)."""
    for r in await server.refs(node_id, 33):
        if r.NodeId.to_string() in above:
            continue
        p = f"{path}/{show(qname(server, r.BrowseName))}"
        td = r.TypeDefinition
        entry = {"path": p, "class": r.NodeClass.name,
                 "type": show(qname(server, await server.c.get_node(td).read_browse_name()))
                 if td.Identifier else None, "data_type": None}
        if r.NodeClass == ua.NodeClass.Variable:
            node = server.c.get_node(r.NodeId)
            dt = await node.read_data_type()
            entry["data_type"] = show(qname(server, await server.c.get_node(dt).read_browse_name()))
            entry["value"] = plain(await node.read_value())
        out.append(entry)
        await tree(server, r.NodeId, p, out, above | {r.NodeId.to_string()})


async def state_machines(server, check, machine, nodes):
    """Each CurrentState with a value names its state: the text is the state's browse
    name, the Id is a state of the machine's type, the Number its StateNumber."""
    by_path = {n["path"]: n for n in nodes}
    for n in nodes:
        if not n["path"].endswith("/CurrentState") or n.get("value") is None:
            continue
        state_id = (by_path.get(n["path"] + "/Id") or {}).get("value")
        if state_id is None:
            check.fail(machine + n["path"], f"{n['value']!r} without its Id")
            continue
        state = server.c.get_node(ua.NodeId.from_string(state_id))
        name = (await state.read_browse_name()).Name
        if name != n["value"]:
            check.fail(machine + n["path"], f"{n['value']!r}, its Id names {name}")
        number = by_path.get(n["path"] + "/Number")
        if number is not None:
            want = await (await state.get_child(["0:StateNumber"])).read_value()
            if number.get("value") != want:
                check.fail(machine + n["path"] + "/Number",
                           f"{number.get('value')}, the StateNumber of {name} is {want}")


async def main():
    url, folder = sys.argv[1:3]
    nodeset = Nodeset(folder)
    async with Client(url, timeout=30) as c:
        uris = await c.get_namespace_array()
        s = Server(c, uris)
        check = Check(s, nodeset)
        for uri in COMPANIONS:
            if uri not in uris:
                check.fail("NamespaceArray", f"{uri} is missing")
        if check.failures:
            print(json.dumps({"namespaces": uris, "failures": check.failures}))
            return
        # The data types as the server defines them (DataTypeDefinition): the
        # enumeration OperationMode has is built from the server's own definition.
        await c.load_data_type_definitions()
        mode = getattr(ua, "MachineOperationMode", None)
        if mode is None or [m.name for m in mode][:2] != ["Manual", "Automatic"]:
            check.fail("DataTypeDefinitions", f"MachineOperationMode not loaded: {mode}")
        machine_tool_type = s.node_id((MACHINE_TOOL, 13))
        machines = s.node_id((MACHINERY, 1001))
        found = []
        for r in await s.refs(machines, 33):
            if r.NodeClass == ua.NodeClass.Object and r.TypeDefinition.Identifier and \
                    await s.is_subtype(r.TypeDefinition, machine_tool_type):
                found.append(r)
        if not found:
            check.fail("Machines", "no object of MachineToolType or a subtype")
        for t in [(MACHINE_TOOL, i) for i in (13, 11, 14, 26, 21, 32, 15, 12, 7)] + \
                 [(MACHINERY, 1002), (MACHINERY, 1008)]:
            await check.same_as_files(t)
        nodes = {}
        for r in found:
            name = show(qname(s, r.BrowseName))
            path = f"Objects/Machinery:Machines/{name}"
            declared = await check.declarations(s.key(r.TypeDefinition))
            await check.instance(r.NodeId, path, declared)
            nodes[name] = []
            await tree(s, r.NodeId, "", nodes[name], {r.NodeId.to_string()})
            await state_machines(s, check, path, nodes[name])
        print(json.dumps({
            "namespaces": uris,
            "machines": [{"name": show(qname(s, r.BrowseName)), "node_id": r.NodeId.to_string(),
                          "type": show(qname(s, await c.get_node(r.TypeDefinition).read_browse_name()))}
                         for r in found],
            "checked": check.checked, "failures": check.failures, "nodes": nodes}))


if __name__ == "__main__":
    asyncio.run(main())
