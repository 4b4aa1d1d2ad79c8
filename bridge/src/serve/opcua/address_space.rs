//! The machine's nodes, as OPC 40501-1 (Machine Tools) defines a machine tool on OPC
//! 40001-1 (Machinery) and DI: `Objects/Machines/<machine>`, a `MachineToolType`, with
//! Identification (`MachineToolIdentificationType`), Monitoring/MachineTool (operation
//! mode, MachineryItemState, MachineryOperationMode), Production/ActiveProgram with its
//! `ProductionProgramStateMachineType`, Equipment and Notification: every component
//! the types mark Mandatory, with the specifications' browse names and types
//! ([`super::companion`]). What is the gateway's own (the measurement state, results,
//! the last runs, the methods) is added where the specification allows additions, with
//! browse names of the gateway's namespace and types of [`super::gateway_types`].
//!
//! Node ids of the machine's nodes are strings `Machine.<path>` in the gateway's
//! namespace (stable, whatever the machine's name).

use super::auth::{ABORT, ACKNOWLEDGE, START_PROGRAM};
use super::companion::{ids, Namespaces};
use super::gateway_types::{self as types, cycle_result_names, CYCLE_RESULTS, RUN_FIELDS};
use opcua::nodes::{ObjectBuilder, VariableBuilder};
use opcua::server::address_space::AddressSpace;
use opcua::types::{
    DataTypeId, LocalizedText, NodeId, ObjectTypeId, QualifiedName, ReferenceTypeId,
    VariableTypeId, Variant,
};
use std::collections::BTreeMap;

/// The namespace of the gateway's nodes.
pub const NAMESPACE: &str = "urn:probebridge:machine";

/// The variables the face keeps up to date, by what they show.
pub struct Nodes {
    pub ns: Namespaces,
    /// Monitoring and Production: name -> node.
    pub state: BTreeMap<&'static str, NodeId>,
    /// Per cycle: `Time`, `ResultNames`, `ResultValues` and one node per result name.
    pub cycles: BTreeMap<u16, CycleNodes>,
    /// Measurements/LastRuns/RunNN, newest first.
    pub runs: Vec<RunNodes>,
}

pub struct CycleNodes {
    pub time: NodeId,
    pub names: NodeId,
    pub values: NodeId,
    pub by_name: BTreeMap<String, NodeId>,
}

/// One run of the history: its fields by name.
pub struct RunNodes {
    pub fields: BTreeMap<&'static str, NodeId>,
}

/// The gateway's own state variables under Monitoring.
const MONITORING: [(&str, DataTypeId); 10] = [
    ("MachineOk", DataTypeId::Boolean),
    ("Bus", DataTypeId::String),
    ("RunState", DataTypeId::String),
    ("RunStateCode", DataTypeId::UInt16),
    ("ProgressPermille", DataTypeId::UInt16),
    ("Point", DataTypeId::UInt16),
    ("ErrorKind", DataTypeId::UInt16),
    ("ErrorCode", DataTypeId::UInt16),
    ("ResultsNotRecorded", DataTypeId::Boolean),
    ("Heartbeat", DataTypeId::UInt16),
];
/// The gateway's own variables of the active program, beside 40501-1's.
const ACTIVE_PROGRAM: [(&str, DataTypeId); 5] = [
    ("Number", DataTypeId::UInt16),
    ("StartedBy", DataTypeId::String),
    ("StartTime", DataTypeId::DateTime),
    ("EndTime", DataTypeId::DateTime),
    ("Cycle", DataTypeId::UInt16),
];

/// What Identification shows (empty: not known, the property has no value).
pub struct Identity {
    pub machine: String,
    pub manufacturer: String,
    pub manufacturer_uri: String,
    pub model: String,
    pub serial_number: String,
    pub bus: String,
    /// The gateway's application URI (host and machine): names the machine when the
    /// manufacturer's URI and the serial number are not configured.
    pub application_uri: String,
}

impl Identity {
    /// DI's ProductInstanceUri, unique per machine: the manufacturer's URI and the
    /// serial number when both are configured, else the gateway's application URI,
    /// which holds the gateway's host name and the machine's.
    pub fn product_instance_uri(&self) -> String {
        if self.manufacturer_uri.is_empty() || self.serial_number.is_empty() {
            self.application_uri.clone()
        } else {
            format!(
                "{}/{}",
                self.manufacturer_uri.trim_end_matches('/'),
                self.serial_number
            )
        }
    }
}

/// What is there of a value: an empty configured text is no value.
fn text(s: &str) -> Variant {
    if s.is_empty() {
        Variant::Empty
    } else {
        Variant::from(s)
    }
}

fn localized(s: &str) -> Variant {
    if s.is_empty() {
        Variant::Empty
    } else {
        Variant::from(LocalizedText::new("", s))
    }
}

/// How a child hangs below its parent.
#[derive(Clone, Copy)]
enum Hang {
    Component,
    Property,
    AddIn,
    Organized,
}

impl Hang {
    fn reference(self) -> ReferenceTypeId {
        match self {
            Hang::Component => ReferenceTypeId::HasComponent,
            Hang::Property => ReferenceTypeId::HasProperty,
            Hang::AddIn => ReferenceTypeId::HasAddIn,
            Hang::Organized => ReferenceTypeId::Organizes,
        }
    }
}

/// A variable to make: its browse name, data type, value rank, type definition.
struct Var {
    name: QualifiedName,
    data_type: NodeId,
    rank: i32,
    type_def: VariableTypeId,
    hang: Hang,
    value: Variant,
}

struct Builder<'a> {
    space: &'a mut AddressSpace,
    ns: Namespaces,
}

impl Builder<'_> {
    fn id(&self, path: &str) -> NodeId {
        if path.is_empty() {
            NodeId::new(self.ns.own, "Machine")
        } else {
            NodeId::new(self.ns.own, format!("Machine.{path}"))
        }
    }

    fn own(&self, name: &str) -> QualifiedName {
        QualifiedName::new(self.ns.own, name)
    }

    /// An object at `path`, below `parent`, of type `type_def`.
    fn object(
        &mut self,
        path: &str,
        name: QualifiedName,
        type_def: NodeId,
        parent: &NodeId,
        hang: Hang,
    ) -> NodeId {
        let id = self.id(path);
        let display = name.name.to_string();
        ObjectBuilder::new(&id, name, display)
            .has_type_definition(type_def)
            .insert(&mut *self.space);
        self.space.insert_reference(parent, &id, hang.reference());
        id
    }

    fn variable(&mut self, path: &str, parent: &NodeId, v: Var) -> NodeId {
        let id = self.id(path);
        let display = v.name.name.to_string();
        VariableBuilder::new(&id, v.name, display)
            .data_type(v.data_type)
            .value_rank(v.rank)
            .value(v.value)
            .minimum_sampling_interval(0.0)
            .has_type_definition(v.type_def)
            .insert(&mut *self.space);
        self.space.insert_reference(parent, &id, v.hang.reference());
        id
    }

    /// One of the gateway's own variables (BaseDataVariableType) below `parent`.
    fn own_variable(
        &mut self,
        path: &str,
        name: &str,
        parent: &NodeId,
        ty: DataTypeId,
        rank: i32,
        value: Variant,
    ) -> NodeId {
        let v = Var {
            name: self.own(name),
            data_type: ty.into(),
            rank,
            type_def: VariableTypeId::BaseDataVariableType,
            hang: Hang::Component,
            value,
        };
        self.variable(path, parent, v)
    }

    /// A property of a companion specification (PropertyType), scalar.
    fn property(
        &mut self,
        path: &str,
        name: QualifiedName,
        parent: &NodeId,
        ty: DataTypeId,
        value: Variant,
    ) -> NodeId {
        let v = Var {
            name,
            data_type: ty.into(),
            rank: -1,
            type_def: VariableTypeId::PropertyType,
            hang: Hang::Property,
            value,
        };
        self.variable(path, parent, v)
    }

    /// A finite state machine's CurrentState (FiniteStateVariableType, LocalizedText)
    /// and its Id (NodeId of the state), below `machine`: (CurrentState, Id).
    fn current_state(&mut self, path: &str, machine: &NodeId) -> (NodeId, NodeId) {
        let v = Var {
            name: QualifiedName::new(0, "CurrentState"),
            data_type: DataTypeId::LocalizedText.into(),
            rank: -1,
            type_def: VariableTypeId::FiniteStateVariableType,
            hang: Hang::Component,
            value: Variant::Empty,
        };
        let current = self.variable(&format!("{path}.CurrentState"), machine, v);
        let id = self.property(
            &format!("{path}.CurrentState.Id"),
            QualifiedName::new(0, "Id"),
            &current,
            DataTypeId::NodeId,
            Variant::Empty,
        );
        (current, id)
    }
}

/// Puts the machine's nodes into `space`, with `last_runs` run objects.
pub fn build(space: &mut AddressSpace, ns: Namespaces, who: &Identity, last_runs: usize) -> Nodes {
    super::gateway_types::build(space, ns);
    let mut b = Builder { space, ns };
    let machine = b.object(
        "",
        b.own(&who.machine),
        ns.machine_tool(ids::MACHINE_TOOL_TYPE),
        &ns.machinery(ids::MACHINES),
        Hang::Organized,
    );
    identification(&mut b, &machine, who);
    let mut state = BTreeMap::new();
    monitoring(&mut b, &machine, who, &mut state);
    production(&mut b, &machine, &mut state);
    for (path, ty) in [
        ("Equipment", ids::EQUIPMENT_TYPE),
        ("Notification", ids::NOTIFICATION_TYPE),
    ] {
        b.object(
            path,
            QualifiedName::new(ns.machine_tool, path),
            ns.machine_tool(ty),
            &machine,
            Hang::Component,
        );
    }
    let (cycles, runs) = measurements(&mut b, &machine, last_runs);
    Nodes {
        ns,
        state,
        cycles,
        runs,
    }
}

/// DI:Identification, a MachineToolIdentificationType, added in (HasAddIn).
fn identification(b: &mut Builder, machine: &NodeId, who: &Identity) {
    let di = b.ns.di;
    let ident = b.object(
        "Identification",
        QualifiedName::new(di, "Identification"),
        b.ns.machine_tool(ids::IDENTIFICATION_TYPE),
        machine,
        Hang::AddIn,
    );
    let mut props = vec![
        (
            "Manufacturer",
            DataTypeId::LocalizedText,
            localized(&who.manufacturer),
        ),
        ("Model", DataTypeId::LocalizedText, localized(&who.model)),
        ("SerialNumber", DataTypeId::String, text(&who.serial_number)),
        (
            "ProductInstanceUri",
            DataTypeId::String,
            Variant::from(who.product_instance_uri()),
        ),
        (
            "SoftwareRevision",
            DataTypeId::String,
            Variant::from(concat!("probebridge ", env!("CARGO_PKG_VERSION"))),
        ),
    ];
    if !who.manufacturer_uri.is_empty() {
        props.push((
            "ManufacturerUri",
            DataTypeId::String,
            text(&who.manufacturer_uri),
        ));
    }
    for (name, ty, value) in props {
        b.property(
            &format!("Identification.{name}"),
            QualifiedName::new(di, name),
            &ident,
            ty,
            value,
        );
    }
}

/// MT:Monitoring with MT:MachineTool (OperationMode, Machinery's MachineryItemState
/// and MachineryOperationMode, also Machinery's building blocks), and the gateway's
/// own state variables.
fn monitoring(
    b: &mut Builder,
    machine: &NodeId,
    who: &Identity,
    state: &mut BTreeMap<&'static str, NodeId>,
) {
    let (mt, m) = (b.ns.machine_tool, b.ns.machinery);
    let monitoring = b.object(
        "Monitoring",
        QualifiedName::new(mt, "Monitoring"),
        b.ns.machine_tool(ids::MONITORING_TYPE),
        machine,
        Hang::Component,
    );
    let tool = b.object(
        "Monitoring.MachineTool",
        QualifiedName::new(mt, "MachineTool"),
        b.ns.machine_tool(ids::MACHINE_OPERATION_MONITORING_TYPE),
        &monitoring,
        Hang::Component,
    );
    let mode = Var {
        name: QualifiedName::new(mt, "OperationMode"),
        data_type: b.ns.machine_tool(ids::MACHINE_OPERATION_MODE),
        rank: -1,
        type_def: VariableTypeId::BaseDataVariableType,
        hang: Hang::Component,
        value: Variant::Empty,
    };
    state.insert(
        "OperationMode",
        b.variable("Monitoring.MachineTool.OperationMode", &tool, mode),
    );
    let blocks = b.object(
        "MachineryBuildingBlocks",
        QualifiedName::new(m, "MachineryBuildingBlocks"),
        ObjectTypeId::FolderType.into(),
        machine,
        Hang::Component,
    );
    for (name, ty, keys) in [
        (
            "MachineryItemState",
            ids::ITEM_STATE_TYPE,
            ["ItemState", "ItemStateId"],
        ),
        (
            "MachineryOperationMode",
            ids::OPERATION_MODE_TYPE,
            ["OperationModeState", "OperationModeStateId"],
        ),
    ] {
        let path = format!("Monitoring.MachineTool.{name}");
        let sm = b.object(
            &path,
            QualifiedName::new(m, name),
            b.ns.machinery(ty),
            &tool,
            Hang::Component,
        );
        b.space
            .insert_reference(&blocks, &sm, ReferenceTypeId::HasAddIn);
        let (current, id) = b.current_state(&path, &sm);
        state.insert(keys[0], current);
        state.insert(keys[1], id);
    }
    for (name, ty) in MONITORING {
        let initial = if name == "Bus" {
            Variant::from(who.bus.as_str())
        } else {
            Variant::Empty
        };
        let id = b.own_variable(
            &format!("Monitoring.{name}"),
            name,
            &monitoring,
            ty,
            -1,
            initial,
        );
        state.insert(name, id);
    }
}

/// MT:Production (the gateway's ProbingProductionType, with the methods) and its
/// ActiveProgram: Name, NumberInList, the ProductionProgramStateMachine, and the
/// gateway's own variables of the run.
fn production(b: &mut Builder, machine: &NodeId, state: &mut BTreeMap<&'static str, NodeId>) {
    let mt = b.ns.machine_tool;
    let production = b.object(
        "Production",
        QualifiedName::new(mt, "Production"),
        types::type_id(b.ns.own, types::PROBING_PRODUCTION_TYPE),
        machine,
        Hang::Component,
    );
    let active = b.object(
        "Production.ActiveProgram",
        QualifiedName::new(mt, "ActiveProgram"),
        b.ns.machine_tool(ids::PRODUCTION_ACTIVE_PROGRAM_TYPE),
        &production,
        Hang::Component,
    );
    // Name is MachineTool's, NumberInList the base namespace's (as the NodeSet has it).
    for (name, ns, ty) in [
        ("Name", mt, DataTypeId::String),
        ("NumberInList", 0, DataTypeId::UInt16),
    ] {
        let id = b.property(
            &format!("Production.ActiveProgram.{name}"),
            QualifiedName::new(ns, name),
            &active,
            ty,
            Variant::Empty,
        );
        state.insert(name, id);
    }
    let sm = b.object(
        "Production.ActiveProgram.State",
        QualifiedName::new(mt, "State"),
        b.ns.machine_tool(ids::PROGRAM_STATE_MACHINE_TYPE),
        &active,
        Hang::Component,
    );
    let (current, id) = b.current_state("Production.ActiveProgram.State", &sm);
    // 40501-1 adds the state's number to its state machines' CurrentState.
    let number = b.property(
        "Production.ActiveProgram.State.CurrentState.Number",
        QualifiedName::new(0, "Number"),
        &current,
        DataTypeId::UInt32,
        Variant::Empty,
    );
    state.insert("ProgramState", current);
    state.insert("ProgramStateId", id);
    state.insert("ProgramStateNumber", number);
    for (name, ty) in ACTIVE_PROGRAM {
        let id = b.own_variable(
            &format!("Production.ActiveProgram.{name}"),
            name,
            &active,
            ty,
            -1,
            Variant::Empty,
        );
        state.insert(name, id);
    }
    for (name, inputs) in [
        (START_PROGRAM, types::start_inputs()),
        (ABORT, Vec::new()),
        (ACKNOWLEDGE, Vec::new()),
    ] {
        let qn = b.own(name);
        let path = format!("Machine.Production.{name}");
        types::method(b.space, b.ns.own, &path, qn, &production, &inputs);
    }
}

/// Measurements (MeasurementsType): the last results of each cycle, the last runs.
fn measurements(
    b: &mut Builder,
    machine: &NodeId,
    last_runs: usize,
) -> (BTreeMap<u16, CycleNodes>, Vec<RunNodes>) {
    let own = b.ns.own;
    let measurements = b.object(
        "Measurements",
        b.own("Measurements"),
        types::type_id(own, types::MEASUREMENTS_TYPE),
        machine,
        Hang::Component,
    );
    let mut cycles = BTreeMap::new();
    for (cycle, names) in cycle_result_names() {
        let base = format!("Measurements.Cycle{cycle}");
        let obj = b.object(
            &base,
            b.own(&format!("Cycle{cycle}")),
            types::type_id(own, types::CYCLE_RESULTS_TYPE),
            &measurements,
            Hang::Component,
        );
        let var = |b: &mut Builder, name: &str, ty, rank| {
            b.own_variable(
                &format!("{base}.{name}"),
                name,
                &obj,
                ty,
                rank,
                Variant::Empty,
            )
        };
        let [time, names_id, values] = CYCLE_RESULTS.map(|(name, ty, rank)| var(b, name, ty, rank));
        let by_name = names
            .iter()
            .map(|n| (n.clone(), var(b, n, DataTypeId::Double, -1)))
            .collect();
        cycles.insert(
            cycle,
            CycleNodes {
                time,
                names: names_id,
                values,
                by_name,
            },
        );
    }
    let last = b.object(
        "Measurements.LastRuns",
        b.own("LastRuns"),
        ObjectTypeId::FolderType.into(),
        &measurements,
        Hang::Component,
    );
    let runs = (1..=last_runs)
        .map(|i| {
            let base = format!("Measurements.LastRuns.Run{i:02}");
            let obj = b.object(
                &base,
                b.own(&format!("Run{i:02}")),
                types::type_id(own, types::MEASUREMENT_RUN_TYPE),
                &last,
                Hang::Organized,
            );
            let fields = RUN_FIELDS
                .iter()
                .map(|&(name, ty, rank)| {
                    let id = b.own_variable(
                        &format!("{base}.{name}"),
                        name,
                        &obj,
                        ty,
                        rank,
                        Variant::Empty,
                    );
                    (name, id)
                })
                .collect();
            RunNodes { fields }
        })
        .collect();
    (cycles, runs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity(manufacturer_uri: &str, serial_number: &str) -> Identity {
        Identity {
            machine: "table-ac".into(),
            manufacturer: "ACME".into(),
            manufacturer_uri: manufacturer_uri.into(),
            model: String::new(),
            serial_number: serial_number.into(),
            bus: "simulator".into(),
            application_uri: "urn:probebridge:gw-7:table-ac".into(),
        }
    }

    /// Unique per machine: the manufacturer's URI with the serial number, else the
    /// gateway's application URI (its host and the machine), never the machine's name
    /// alone (it repeated across gateways, issue 36).
    #[test]
    fn the_product_instance_uri_names_one_machine() {
        let uri = |m: &str, s: &str| identity(m, s).product_instance_uri();
        assert_eq!(
            uri("https://machines.acme.example/", "SN-0451"),
            "https://machines.acme.example/SN-0451"
        );
        for (m, s) in [
            ("", "SN-0451"),
            ("https://machines.acme.example", ""),
            ("", ""),
        ] {
            assert_eq!(uri(m, s), "urn:probebridge:gw-7:table-ac", "{m:?} {s:?}");
        }
    }
}
