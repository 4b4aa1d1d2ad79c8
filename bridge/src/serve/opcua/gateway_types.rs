//! The gateway's own types, in its namespace, where OPC 40501-1 allows additions: the
//! probe measurements (`MeasurementsType` with a `CycleResultsType` per cycle and the
//! history's last runs as `MeasurementRunType`s) and `ProbingProductionType`, the
//! Machine Tools ProductionType with the methods StartProgram, Abort and Acknowledge.
//! Exported as type nodes, so that a client reads what a gateway's machine has from
//! the types, as it does for the companion specifications'.

use super::address_space::RUN_FIELDS;
use super::companion::{ids, Namespaces};
use opcua::nodes::{MethodBuilder, ObjectBuilder, ObjectTypeBuilder, VariableBuilder};
use opcua::server::address_space::AddressSpace;
use opcua::types::{
    Argument, DataTypeId, LocalizedText, NodeId, ObjectId, ObjectTypeId, QualifiedName,
    ReferenceTypeId, UAString, VariableTypeId,
};

pub const MEASUREMENTS_TYPE: &str = "MeasurementsType";
pub const CYCLE_RESULTS_TYPE: &str = "CycleResultsType";
pub const MEASUREMENT_RUN_TYPE: &str = "MeasurementRunType";
pub const PROBING_PRODUCTION_TYPE: &str = "ProbingProductionType";

/// What every cycle's results object has, besides a variable per result.
pub const CYCLE_RESULTS: [(&str, DataTypeId, i32); 3] = [
    ("Time", DataTypeId::DateTime, -1),
    ("ResultNames", DataTypeId::String, 1),
    ("ResultValues", DataTypeId::Double, 1),
];

/// The cycles with a results object under Measurements.
pub const CYCLES: [u16; 4] = [431, 444, 451, 460];

pub fn type_id(ns: u16, name: &str) -> NodeId {
    NodeId::new(ns, format!("Types.{name}"))
}

fn mandatory(space: &mut AddressSpace, node: &NodeId) {
    space.insert_reference(
        node,
        &ObjectId::ModellingRule_Mandatory.into(),
        ReferenceTypeId::HasModellingRule,
    );
}

pub fn argument(name: &str, ty: DataTypeId, rank: i32, description: &str) -> Argument {
    Argument {
        name: UAString::from(name),
        data_type: ty.into(),
        value_rank: rank,
        array_dimensions: (rank == 1).then(|| vec![0]),
        description: LocalizedText::from(description),
    }
}

/// StartProgram's inputs, Number, Parameters and Confirm.
pub fn start_inputs() -> Vec<Argument> {
    vec![
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
    ]
}

/// Every method's outputs: the PLC face's reason and its words.
pub fn method_outputs() -> Vec<Argument> {
    vec![
        argument(
            "Reason",
            DataTypeId::UInt16,
            -1,
            "0: taken; else the PLC face's reason",
        ),
        argument("ReasonText", DataTypeId::String, -1, "the reason in words"),
    ]
}

/// A method `ns;s=PATH` with its arguments (`PATH.InputArguments`,
/// `PATH.OutputArguments`), below `parent` (an object or an object type).
pub fn method(
    space: &mut AddressSpace,
    ns: u16,
    path: &str,
    name: QualifiedName,
    parent: &NodeId,
    inputs: &[Argument],
) -> NodeId {
    let id = NodeId::new(ns, path);
    let display = name.name.to_string();
    let mut b = MethodBuilder::new(&id, name, display)
        .component_of(parent.clone())
        .executable(true)
        .user_executable(true);
    if !inputs.is_empty() {
        b = b.input_args(
            space,
            &NodeId::new(ns, format!("{path}.InputArguments")),
            inputs,
        );
    }
    b = b.output_args(
        space,
        &NodeId::new(ns, format!("{path}.OutputArguments")),
        &method_outputs(),
    );
    b.insert(space);
    id
}

/// The gateway's types, into `space`.
pub fn build(space: &mut AddressSpace, ns: Namespaces) {
    let own = ns.own;
    let qn = |name: &str| QualifiedName::new(own, name);
    let object_type = |space: &mut AddressSpace, name: &str, parent: NodeId| {
        let id = type_id(own, name);
        ObjectTypeBuilder::new(&id, qn(name), name)
            .subtype_of(parent)
            .insert(space);
        id
    };
    let var = |space: &mut AddressSpace, ty: &str, (name, dt, rank): (&str, DataTypeId, i32)| {
        let id = NodeId::new(own, format!("Types.{ty}.{name}"));
        VariableBuilder::new(&id, qn(name), name)
            .data_type(dt)
            .value_rank(rank)
            .has_type_definition(VariableTypeId::BaseDataVariableType)
            .component_of(type_id(own, ty))
            .insert(space);
        mandatory(space, &id);
    };
    let cycle = object_type(
        space,
        CYCLE_RESULTS_TYPE,
        ObjectTypeId::BaseObjectType.into(),
    );
    for v in CYCLE_RESULTS {
        var(space, CYCLE_RESULTS_TYPE, v);
    }
    object_type(
        space,
        MEASUREMENT_RUN_TYPE,
        ObjectTypeId::BaseObjectType.into(),
    );
    for v in RUN_FIELDS {
        var(space, MEASUREMENT_RUN_TYPE, v);
    }
    let measurements = object_type(
        space,
        MEASUREMENTS_TYPE,
        ObjectTypeId::BaseObjectType.into(),
    );
    let child = |space: &mut AddressSpace, name: &str, ty: NodeId| {
        let id = NodeId::new(own, format!("Types.{MEASUREMENTS_TYPE}.{name}"));
        ObjectBuilder::new(&id, qn(name), name)
            .has_type_definition(ty)
            .component_of(measurements.clone())
            .insert(space);
        mandatory(space, &id);
    };
    child(space, "LastRuns", ObjectTypeId::FolderType.into());
    for c in CYCLES {
        child(space, &format!("Cycle{c}"), cycle.clone());
    }
    let production = object_type(
        space,
        PROBING_PRODUCTION_TYPE,
        ns.machine_tool(ids::PRODUCTION_TYPE),
    );
    for (name, inputs) in [
        (super::auth::START_PROGRAM, start_inputs()),
        (super::auth::ABORT, Vec::new()),
        (super::auth::ACKNOWLEDGE, Vec::new()),
    ] {
        let path = format!("Types.{PROBING_PRODUCTION_TYPE}.{name}");
        let id = method(space, own, &path, qn(name), &production, &inputs);
        mandatory(space, &id);
        for args in ["InputArguments", "OutputArguments"] {
            let arg = NodeId::new(
                own,
                format!("Types.{PROBING_PRODUCTION_TYPE}.{name}.{args}"),
            );
            if space.node_exists(&arg) {
                mandatory(space, &arg);
            }
        }
    }
}
