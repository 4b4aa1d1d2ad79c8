//! The OPC Foundation's companion specifications the face is built on (OPC 40501-1
//! Machine Tools on OPC 40001-1 Machinery, DI and IA), loaded from their NodeSet2 files
//! as published (`third_party/opcua-nodesets/`, MIT licence in each header), which the
//! binary carries: a gateway needs no file beside it to describe itself.
//!
//! The node ids of the types and states the gateway's machine uses are named here, by
//! their specification's numbers.

use opcua::nodes::{ImportedItem, NodeSet2Import, NodeSetImport, NodeSetNamespaceMapper};
use opcua::types::NodeId;

pub const DI: &str = "http://opcfoundation.org/UA/DI/";
pub const IA: &str = "http://opcfoundation.org/UA/IA/";
pub const MACHINERY: &str = "http://opcfoundation.org/UA/Machinery/";
pub const MACHINERY_JOBS: &str = "http://opcfoundation.org/UA/Machinery/Jobs/";
pub const ISA95_JOB_CONTROL: &str = "http://opcfoundation.org/UA/ISA95-JOBCONTROL_V2/";
pub const MACHINE_TOOL: &str = "http://opcfoundation.org/UA/MachineTool/";

/// The NodeSet2 files in load order (each after those it requires): file name, text.
pub const NODESETS: [(&str, &str); 6] = [
    (
        "Opc.Ua.Di.NodeSet2.xml",
        include_str!("../../../../third_party/opcua-nodesets/Opc.Ua.Di.NodeSet2.xml"),
    ),
    (
        "Opc.Ua.IA.NodeSet2.xml",
        include_str!("../../../../third_party/opcua-nodesets/Opc.Ua.IA.NodeSet2.xml"),
    ),
    (
        "opc.ua.isa95-jobcontrol.nodeset2.xml",
        include_str!("../../../../third_party/opcua-nodesets/opc.ua.isa95-jobcontrol.nodeset2.xml"),
    ),
    (
        "Opc.Ua.Machinery.NodeSet2.xml",
        include_str!("../../../../third_party/opcua-nodesets/Opc.Ua.Machinery.NodeSet2.xml"),
    ),
    (
        "Opc.Ua.Machinery.Jobs.Nodeset2.xml",
        include_str!("../../../../third_party/opcua-nodesets/Opc.Ua.Machinery.Jobs.Nodeset2.xml"),
    ),
    (
        "Opc.Ua.MachineTool.NodeSet2.xml",
        include_str!("../../../../third_party/opcua-nodesets/Opc.Ua.MachineTool.NodeSet2.xml"),
    ),
];

/// One NodeSet2 file to import. The namespaces are registered here rather than by
/// async-opcua's importer, which prints each one on stdout (the gateway's stdout says
/// what it serves, nothing else).
struct Nodeset {
    import: NodeSet2Import,
    /// The file's NamespaceUris, in order: its `ns=1`, `ns=2`, ...
    uris: Vec<String>,
}

impl NodeSetImport for Nodeset {
    fn register_namespaces(&self, namespaces: &mut NodeSetNamespaceMapper) {
        for (i, uri) in self.uris.iter().enumerate() {
            // The file's index i + 1 (0 is the base namespace); at most a few.
            namespaces.add_namespace(uri, u16::try_from(i + 1).unwrap_or(u16::MAX));
        }
    }

    fn get_own_namespaces(&self) -> Vec<String> {
        self.import.get_own_namespaces()
    }

    fn load<'a>(
        &'a self,
        namespaces: &'a NodeSetNamespaceMapper,
    ) -> Box<dyn Iterator<Item = ImportedItem> + 'a> {
        self.import.load(namespaces)
    }
}

/// The gateway's own namespace, as an import without nodes: so that it is a namespace
/// of the same node manager as the companion specifications' (the machine's nodes
/// reference theirs, and Machines organizes the machine).
struct Own(&'static str);

impl NodeSetImport for Own {
    fn register_namespaces(&self, namespaces: &mut NodeSetNamespaceMapper) {
        namespaces.add_namespace(self.0, 1);
    }

    fn get_own_namespaces(&self) -> Vec<String> {
        vec![self.0.to_owned()]
    }

    fn load<'a>(
        &'a self,
        _namespaces: &'a NodeSetNamespaceMapper,
    ) -> Box<dyn Iterator<Item = ImportedItem> + 'a> {
        Box::new(std::iter::empty())
    }
}

/// The imports of the companion specifications, then the gateway's namespace `own`.
pub fn imports(own: &'static str) -> Result<Vec<Box<dyn NodeSetImport>>, String> {
    let mut out: Vec<Box<dyn NodeSetImport>> = Vec::new();
    for (file, text) in NODESETS {
        let import = NodeSet2Import::new_str("en", text, Vec::new())
            .map_err(|e| format!("the companion NodeSet {file}: {e}"))?;
        let uris = import.get_own_namespaces();
        if uris.is_empty() {
            return Err(format!("the companion NodeSet {file} names no namespace"));
        }
        out.push(Box::new(Nodeset { import, uris }));
    }
    out.push(Box::new(Own(own)));
    Ok(out)
}

/// The namespace indexes of the server, by URI.
#[derive(Clone, Copy, Debug)]
pub struct Namespaces {
    pub own: u16,
    pub di: u16,
    pub machinery: u16,
    pub machine_tool: u16,
}

impl Namespaces {
    pub fn di(&self, i: u32) -> NodeId {
        NodeId::new(self.di, i)
    }
    pub fn machinery(&self, i: u32) -> NodeId {
        NodeId::new(self.machinery, i)
    }
    pub fn machine_tool(&self, i: u32) -> NodeId {
        NodeId::new(self.machine_tool, i)
    }
}

/// Node ids of the specifications (numbers of their NodeSet files).
pub mod ids {
    /// Machinery: the Machines folder (OPC 40001-1, 8.1).
    pub const MACHINES: u32 = 1001;
    /// Machinery: MachineryItemState_StateMachineType and its states.
    pub const ITEM_STATE_TYPE: u32 = 1002;
    pub const ITEM_STATE_OUT_OF_SERVICE: u32 = 5004;
    pub const ITEM_STATE_EXECUTING: u32 = 5006;
    pub const ITEM_STATE_NOT_EXECUTING: u32 = 5007;
    /// Machinery: MachineryOperationModeStateMachineType and its states.
    pub const OPERATION_MODE_TYPE: u32 = 1008;
    pub const OPERATION_MODE_NONE: u32 = 5024;
    pub const OPERATION_MODE_PROCESSING: u32 = 5026;
    /// MachineTool (OPC 40501-1): the types of the machine and its parts.
    pub const NOTIFICATION_TYPE: u32 = 7;
    pub const IDENTIFICATION_TYPE: u32 = 11;
    pub const EQUIPMENT_TYPE: u32 = 12;
    pub const MACHINE_TOOL_TYPE: u32 = 13;
    pub const MONITORING_TYPE: u32 = 14;
    pub const PROGRAM_STATE_MACHINE_TYPE: u32 = 15;
    pub const PRODUCTION_TYPE: u32 = 21;
    pub const MACHINE_OPERATION_MONITORING_TYPE: u32 = 26;
    pub const PRODUCTION_ACTIVE_PROGRAM_TYPE: u32 = 32;
    /// MachineTool: the enumeration MachineOperationMode.
    pub const MACHINE_OPERATION_MODE: u32 = 65;
    /// MachineTool: ProductionStateMachineType's states (those a run passes).
    pub const PROGRAM_RUNNING: u32 = 138;
    pub const PROGRAM_ENDED: u32 = 140;
    pub const PROGRAM_ABORTED: u32 = 141;
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::server::address_space::AddressSpace;
    use opcua::types::NamespaceMap;

    /// The six NodeSets import into one address space, beside the gateway's namespace,
    /// with the types and states the machine's nodes name.
    #[test]
    fn the_nodesets_load_with_the_nodes_the_machine_names() {
        let mut space = AddressSpace::new();
        let mut namespaces = NamespaceMap::new();
        for import in imports("urn:probebridge:test").unwrap() {
            space.import_node_set(&*import, &mut namespaces);
        }
        let index = |uri: &str| namespaces.get_index(uri).unwrap();
        let ns = Namespaces {
            own: index("urn:probebridge:test"),
            di: index(DI),
            machinery: index(MACHINERY),
            machine_tool: index(MACHINE_TOOL),
        };
        for uri in [IA, MACHINERY_JOBS, ISA95_JOB_CONTROL] {
            index(uri);
        }
        let named = [
            ns.machinery(ids::MACHINES),
            ns.machinery(ids::ITEM_STATE_TYPE),
            ns.machinery(ids::ITEM_STATE_OUT_OF_SERVICE),
            ns.machinery(ids::ITEM_STATE_EXECUTING),
            ns.machinery(ids::ITEM_STATE_NOT_EXECUTING),
            ns.machinery(ids::OPERATION_MODE_TYPE),
            ns.machinery(ids::OPERATION_MODE_NONE),
            ns.machinery(ids::OPERATION_MODE_PROCESSING),
            ns.machine_tool(ids::NOTIFICATION_TYPE),
            ns.machine_tool(ids::IDENTIFICATION_TYPE),
            ns.machine_tool(ids::EQUIPMENT_TYPE),
            ns.machine_tool(ids::MACHINE_TOOL_TYPE),
            ns.machine_tool(ids::MONITORING_TYPE),
            ns.machine_tool(ids::PROGRAM_STATE_MACHINE_TYPE),
            ns.machine_tool(ids::PRODUCTION_TYPE),
            ns.machine_tool(ids::MACHINE_OPERATION_MONITORING_TYPE),
            ns.machine_tool(ids::PRODUCTION_ACTIVE_PROGRAM_TYPE),
            ns.machine_tool(ids::MACHINE_OPERATION_MODE),
            ns.machine_tool(ids::PROGRAM_RUNNING),
            ns.machine_tool(ids::PROGRAM_ENDED),
            ns.machine_tool(ids::PROGRAM_ABORTED),
            ns.di(15035),
        ];
        for id in named {
            assert!(space.node_exists(&id), "{id}");
        }
        let name = |id: NodeId| {
            space
                .find(&id)
                .unwrap()
                .as_node()
                .browse_name()
                .name
                .to_string()
        };
        assert_eq!(
            name(ns.machine_tool(ids::MACHINE_TOOL_TYPE)),
            "MachineToolType"
        );
        assert_eq!(name(ns.machine_tool(ids::PROGRAM_ABORTED)), "Aborted");
        assert_eq!(
            name(ns.machinery(ids::OPERATION_MODE_PROCESSING)),
            "Processing"
        );
    }
}
