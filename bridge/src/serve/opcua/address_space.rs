//! The machine's nodes, after OPC 40501-1 (Machine Tools) on OPC 40001-1 (Machinery):
//! `Objects/Machines/<machine>` with Identification, MachineryItemState, Monitoring,
//! Production (the active program and the methods) and the probe measurements. The
//! companion NodeSets are not loaded: the same browse names live in the gateway's
//! own namespace, and the gateway page of the docs says how each maps.
//!
//! Node ids are strings `Machine.<path>` (stable, whatever the machine's name); the
//! browse names carry the names a client browses by.

use super::super::results::{slots, Quantity, ResultKey, CAL_COLUMNS};
use super::auth::{ABORT, ACKNOWLEDGE, START_PROGRAM};
use opcua::nodes::{MethodBuilder, ObjectBuilder, VariableBuilder};
use opcua::server::address_space::AddressSpace;
use opcua::types::{
    Argument, DataTypeId, LocalizedText, NodeId, ObjectId, ObjectTypeId, QualifiedName, UAString,
    VariableTypeId, Variant,
};
use std::collections::BTreeMap;

/// The namespace of the gateway's nodes.
pub const NAMESPACE: &str = "urn:probebridge:machine";

/// The cycles with a results object, and the result names each shows: the PLC face's
/// result slots of each cycle, and for 460 its calibration block (the probe table row
/// and the columns' standard uncertainties).
pub fn cycle_result_names() -> Vec<(u16, Vec<String>)> {
    let q = |r: std::ops::RangeInclusive<u16>| r.map(|n| format!("Q{n}")).collect::<Vec<_>>();
    let mut c431 = q(158..=159);
    c431.extend(q(170..=175));
    let mut c444 = q(151..=153);
    c444.extend(q(161..=164));
    c444.push("Q183".into());
    let mut c451 = q(141..=149);
    c451.extend(
        slots()
            .into_iter()
            .filter(|q| !matches!(q, Quantity::Named(_)))
            .map(|q| q.to_string()),
    );
    let mut c460: Vec<String> = CAL_COLUMNS.iter().map(|c| c.to_string()).collect();
    c460.extend(
        CAL_COLUMNS
            .iter()
            .map(|c| ResultKey::Uncertainty(Quantity::named(c)).to_string()),
    );
    vec![(431, c431), (444, c444), (451, c451), (460, c460)]
}

/// The variables the face keeps up to date, by what they show.
pub struct Nodes {
    pub ns: u16,
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

/// The state variables: (browse name, parent, data type, initial value).
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
const ACTIVE_PROGRAM: [(&str, DataTypeId); 7] = [
    ("Name", DataTypeId::String),
    ("Number", DataTypeId::UInt16),
    ("State", DataTypeId::String),
    ("StartedBy", DataTypeId::String),
    ("StartTime", DataTypeId::DateTime),
    ("EndTime", DataTypeId::DateTime),
    ("Cycle", DataTypeId::UInt16),
];
pub const RUN_FIELDS: [(&str, DataTypeId, i32); 12] = [
    ("Id", DataTypeId::Int64, -1),
    ("Status", DataTypeId::String, -1),
    ("Source", DataTypeId::String, -1),
    ("ProgramNumber", DataTypeId::UInt16, -1),
    ("Program", DataTypeId::String, -1),
    ("Started", DataTypeId::DateTime, -1),
    ("Finished", DataTypeId::DateTime, -1),
    ("Message", DataTypeId::String, -1),
    ("Parameters", DataTypeId::Double, 1),
    ("ResultNames", DataTypeId::String, 1),
    ("ResultValues", DataTypeId::Double, 1),
    // How long the run's cycles kept the machine, s.
    ("MachineTime", DataTypeId::Double, -1),
];

/// What Identification shows.
pub struct Identity {
    pub machine: String,
    pub manufacturer: String,
    pub model: String,
    pub serial_number: String,
    pub bus: String,
}

struct Builder<'a> {
    space: &'a mut AddressSpace,
    ns: u16,
}

impl Builder<'_> {
    fn id(&self, path: &str) -> NodeId {
        NodeId::new(self.ns, format!("Machine.{path}"))
    }

    fn qn(&self, name: &str) -> QualifiedName {
        QualifiedName::new(self.ns, name)
    }

    fn object(&mut self, path: &str, name: &str, parent: &NodeId, folder: bool) -> NodeId {
        let id = self.id(path);
        let b = ObjectBuilder::new(&id, self.qn(name), name);
        let b = if folder {
            b.has_type_definition(ObjectTypeId::FolderType)
                .organized_by(parent.clone())
        } else {
            b.has_type_definition(ObjectTypeId::BaseObjectType)
                .component_of(parent.clone())
        };
        b.insert(&mut *self.space);
        id
    }

    fn variable(
        &mut self,
        path: &str,
        name: &str,
        parent: &NodeId,
        ty: DataTypeId,
        rank: i32,
        value: Variant,
    ) -> NodeId {
        let id = self.id(path);
        let b = VariableBuilder::new(&id, self.qn(name), name)
            .data_type(ty)
            .value_rank(rank)
            .value(value)
            .minimum_sampling_interval(0.0)
            .has_type_definition(VariableTypeId::BaseDataVariableType)
            .component_of(parent.clone());
        b.insert(&mut *self.space);
        id
    }

    fn property(&mut self, path: &str, name: &str, parent: &NodeId, value: &str) {
        let id = self.id(path);
        VariableBuilder::new(&id, self.qn(name), name)
            .data_type(DataTypeId::String)
            .value(Variant::from(value))
            .has_type_definition(VariableTypeId::PropertyType)
            .property_of(parent.clone())
            .insert(&mut *self.space);
    }

    fn method(&mut self, name: &str, parent: &NodeId, inputs: &[Argument]) -> NodeId {
        let id = NodeId::new(self.ns, format!("Machine.Production.{name}"));
        let mut b = MethodBuilder::new(&id, self.qn(name), name)
            .component_of(parent.clone())
            .executable(true)
            .user_executable(true);
        if !inputs.is_empty() {
            b = b.input_args(
                &mut *self.space,
                &NodeId::new(self.ns, format!("Machine.Production.{name}.InputArguments")),
                inputs,
            );
        }
        b = b.output_args(
            &mut *self.space,
            &NodeId::new(
                self.ns,
                format!("Machine.Production.{name}.OutputArguments"),
            ),
            &[
                argument(
                    "Reason",
                    DataTypeId::UInt16,
                    -1,
                    "0: taken; else the PLC face's reason",
                ),
                argument("ReasonText", DataTypeId::String, -1, "the reason in words"),
            ],
        );
        b.insert(&mut *self.space);
        id
    }
}

fn argument(name: &str, ty: DataTypeId, rank: i32, description: &str) -> Argument {
    Argument {
        name: UAString::from(name),
        data_type: ty.into(),
        value_rank: rank,
        array_dimensions: (rank == 1).then(|| vec![0]),
        description: LocalizedText::from(description),
    }
}

/// Puts the machine's nodes into `space` (namespace `ns`), `last_runs` run objects.
pub fn build(space: &mut AddressSpace, ns: u16, who: &Identity, last_runs: usize) -> Nodes {
    let mut b = Builder { space, ns };
    let objects: NodeId = ObjectId::ObjectsFolder.into();
    let machines = b.object("Machines", "Machines", &objects, true);
    let machine = {
        let id = b.id("Machine");
        ObjectBuilder::new(&id, b.qn(&who.machine), who.machine.as_str())
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .organized_by(machines.clone())
            .insert(&mut *b.space);
        id
    };
    let ident = b.object("Identification", "Identification", &machine, false);
    let uri = format!("urn:probebridge:{}", who.machine);
    for (name, value) in [
        ("Manufacturer", who.manufacturer.as_str()),
        ("Model", who.model.as_str()),
        ("SerialNumber", who.serial_number.as_str()),
        ("ProductInstanceUri", uri.as_str()),
        (
            "SoftwareRevision",
            concat!("probebridge ", env!("CARGO_PKG_VERSION")),
        ),
    ] {
        b.property(&format!("Identification.{name}"), name, &ident, value);
    }
    let mut state = BTreeMap::new();
    state_nodes(&mut b, &machine, who, &mut state);
    production(&mut b, &machine, &mut state);
    let (cycles, runs) = measurements(&mut b, &machine, last_runs);
    Nodes {
        ns,
        state,
        cycles,
        runs,
    }
}

/// MachineryItemState and Monitoring.
fn state_nodes(
    b: &mut Builder,
    machine: &NodeId,
    who: &Identity,
    state: &mut BTreeMap<&'static str, NodeId>,
) {
    let item_state = b.object("MachineryItemState", "MachineryItemState", machine, false);
    state.insert(
        "CurrentState",
        b.variable(
            "MachineryItemState.CurrentState",
            "CurrentState",
            &item_state,
            DataTypeId::String,
            -1,
            Variant::from("NotAvailable"),
        ),
    );
    let monitoring = b.object("Monitoring", "Monitoring", machine, false);
    for (name, ty) in MONITORING {
        let initial = if name == "Bus" {
            Variant::from(who.bus.as_str())
        } else {
            Variant::Empty
        };
        let id = b.variable(
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

/// Production: the active program and the methods.
fn production(b: &mut Builder, machine: &NodeId, state: &mut BTreeMap<&'static str, NodeId>) {
    let production = b.object("Production", "Production", machine, false);
    let active = b.object(
        "Production.ActiveProgram",
        "ActiveProgram",
        &production,
        false,
    );
    for (name, ty) in ACTIVE_PROGRAM {
        let id = b.variable(
            &format!("Production.ActiveProgram.{name}"),
            name,
            &active,
            ty,
            -1,
            Variant::Empty,
        );
        state.insert(name, id);
    }
    b.method(
        START_PROGRAM,
        &production,
        &[
            argument(
                "Number",
                DataTypeId::UInt16,
                -1,
                "the program NNN.h of the program folder",
            ),
            argument(
                "Parameters",
                DataTypeId::Float,
                1,
                "the request's parameters 1..8",
            ),
            argument(
                "Confirm",
                DataTypeId::Boolean,
                -1,
                "go on where a cycle asks to confirm",
            ),
        ],
    );
    b.method(ABORT, &production, &[]);
    b.method(ACKNOWLEDGE, &production, &[]);
}

/// Measurements: the last results of each cycle, the last runs.
fn measurements(
    b: &mut Builder,
    machine: &NodeId,
    last_runs: usize,
) -> (BTreeMap<u16, CycleNodes>, Vec<RunNodes>) {
    let measurements = b.object("Measurements", "Measurements", machine, false);
    let mut cycles = BTreeMap::new();
    for (cycle, names) in cycle_result_names() {
        let base = format!("Measurements.Cycle{cycle}");
        let obj = b.object(&base, &format!("Cycle{cycle}"), &measurements, false);
        let var = |b: &mut Builder, name: &str, ty, rank| {
            b.variable(
                &format!("{base}.{name}"),
                name,
                &obj,
                ty,
                rank,
                Variant::Empty,
            )
        };
        let time = var(b, "Time", DataTypeId::DateTime, -1);
        let names_id = var(b, "ResultNames", DataTypeId::String, 1);
        let values = var(b, "ResultValues", DataTypeId::Double, 1);
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
    let last = b.object("Measurements.LastRuns", "LastRuns", &measurements, false);
    let runs = (1..=last_runs)
        .map(|i| {
            let base = format!("Measurements.LastRuns.Run{i:02}");
            let obj = b.object(&base, &format!("Run{i:02}"), &last, false);
            let fields = RUN_FIELDS
                .iter()
                .map(|&(name, ty, rank)| {
                    let id = b.variable(
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
