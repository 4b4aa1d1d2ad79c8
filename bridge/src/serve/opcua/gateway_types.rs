//! The gateway's own types, in its namespace, where OPC 40501-1 allows additions: the
//! probe measurements (`MeasurementsType` with a `CycleResultsType` per cycle and the
//! history's last runs as `MeasurementRunType`s) and `ProbingProductionType`, the
//! Machine Tools ProductionType with the methods StartProgram, Abort and Acknowledge.
//! Exported as type nodes, so that a client reads what a gateway's machine has from
//! the types, as it does for the companion specifications'.

use super::super::results::{slots, Quantity, ResultKey, CAL_COLUMNS};
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

/// The fields of a run of the history (MeasurementRunType): name, data type, rank.
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

/// The cycles with a results object, and the result names each shows: the PLC face's
/// result slots of each cycle, each with its standard uncertainty (`u.NAME`) where the
/// cycle gives one (431 every result, 444 the point and deviation, 451 the errors
/// after optimisation), and for 460 its calibration block (the probe table row and the
/// columns' standard uncertainties).
pub fn cycle_result_names() -> Vec<(u16, Vec<String>)> {
    let q = |r: std::ops::RangeInclusive<u16>| r.map(|n| format!("Q{n}")).collect::<Vec<_>>();
    let u = |names: &[String]| -> Vec<String> {
        names
            .iter()
            .map(|n| ResultKey::Uncertainty(Quantity::named(n)).to_string())
            .collect()
    };
    let mut c431 = q(158..=159);
    c431.extend(q(170..=175));
    c431.extend(u(&c431));
    let mut c444 = q(151..=153);
    c444.extend(q(161..=164));
    c444.extend(u(&c444));
    c444.push("Q183".into());
    let mut c451 = q(141..=149);
    let errors: Vec<Quantity> = slots()
        .into_iter()
        .filter(|q| !matches!(q, Quantity::Named(_)))
        .collect();
    c451.extend(errors.iter().map(ToString::to_string));
    c451.extend(
        errors
            .into_iter()
            .filter(|q| matches!(q, Quantity::ErrorAfter(_)))
            .map(|q| ResultKey::Uncertainty(q).to_string()),
    );
    let mut c460: Vec<String> = CAL_COLUMNS.iter().map(|c| c.to_string()).collect();
    c460.extend(u(&c460));
    vec![(431, c431), (444, c444), (451, c451), (460, c460)]
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// Every result the faces list has a node, and so has its uncertainty where the
    /// cycle gives one (issue 36: `u.Q158` was listed and held by no node).
    #[test]
    fn each_result_and_its_uncertainty_has_a_node() {
        let names: BTreeMap<u16, Vec<String>> = cycle_result_names().into_iter().collect();
        let has = |c: u16, n: &str| names[&c].iter().any(|x| x == n);
        for n in ["Q158", "u.Q158", "Q175", "u.Q175"] {
            assert!(has(431, n), "431 {n}");
        }
        for n in ["Q151", "u.Q151", "Q164", "u.Q164", "Q183"] {
            assert!(has(444, n), "444 {n}");
        }
        assert!(!has(444, "u.Q183"), "444 gives no uncertainty of Q183");
        for n in ["Q141", "before.EX0C", "after.EX0C", "u.after.EX0C"] {
            assert!(has(451, n), "451 {n}");
        }
        assert!(!has(451, "u.before.EX0C"), "451's errors before have none");
        for n in ["R", "u.R", "L", "u.L"] {
            assert!(has(460, n), "460 {n}");
        }
        let types: Vec<u16> = CYCLES.to_vec();
        assert_eq!(names.keys().copied().collect::<Vec<_>>(), types);
    }
}
