//! Keeps the machine's variables up to date: on every change the measurement service
//! announces, the face takes a snapshot of it under the gateway's lock, and writes only the
//! variables whose value changed (each change reaches a subscriber once). The last
//! runs are read from the history when a run has ended.

use super::address_space::Nodes;
use super::companion::ids;
use super::gateway_types::RUN_FIELDS;
use crate::history::{Filter, History, HistoryTarget, RunRow};
use crate::serve::gateway::{lock, Shared};
use crate::serve::measurement::{Face, State};
use crate::serve::outcome::Outcome;
use crate::serve::results::Quantity;
use crate::serve::service::RunInfo;
use opcua::server::node_manager::memory::SimpleNodeManager;
use opcua::server::SubscriptionCache;
use opcua::types::{DataValue, DateTime, LocalizedText, NodeId, Variant};
use std::collections::{BTreeMap, HashMap};
use std::str::FromStr;
use std::sync::Arc;
use std::time::SystemTime;

/// Where the values go.
pub struct Publisher {
    pub nodes: Nodes,
    pub manager: Arc<SimpleNodeManager>,
    pub subscriptions: Arc<SubscriptionCache>,
    pub history: Option<HistoryTarget>,
    pub machine: String,
    /// The values last written, to write only changes.
    last: HashMap<NodeId, Variant>,
}

/// 100 ns ticks between 1601-01-01 (OPC UA's epoch) and 1970-01-01.
const UNIX_EPOCH_TICKS: i64 = 116_444_736_000_000_000;

fn date_time(t: SystemTime) -> Variant {
    match t.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(d) => Variant::from(DateTime::from(
            UNIX_EPOCH_TICKS + i64::try_from(d.as_nanos() / 100).unwrap_or(0),
        )),
        Err(_) => Variant::Empty,
    }
}

fn date_time_text(s: Option<&str>) -> Variant {
    s.and_then(|s| DateTime::from_str(s).ok())
        .map_or(Variant::Empty, Variant::from)
}

/// Machinery's MachineryItemState: what the gateway's machine does. Out of service
/// while the machine is not ok (bus down, drives faulted), executing while a
/// measurement runs, else not executing.
fn item_state(state: State, machine_ok: bool) -> (&'static str, u32) {
    match (machine_ok, state) {
        (false, _) => ("OutOfService", ids::ITEM_STATE_OUT_OF_SERVICE),
        (true, State::Busy) => ("Executing", ids::ITEM_STATE_EXECUTING),
        (true, _) => ("NotExecuting", ids::ITEM_STATE_NOT_EXECUTING),
    }
}

/// Machinery's MachineryOperationMode and 40501-1's MachineOperationMode as far as the
/// gateway knows them: while it runs a measuring program the machine processes it in
/// automatic operation; otherwise the gateway does not know the CNC's mode: Machinery's
/// "None" (no operation mode available) and no OperationMode value.
fn operation_mode(state: State) -> ((&'static str, u32), Option<i32>) {
    if state == State::Busy {
        (("Processing", ids::OPERATION_MODE_PROCESSING), Some(1))
    } else {
        (("None", ids::OPERATION_MODE_NONE), None)
    }
}

/// OPC 40501-1's program state of a run (ProductionStateMachineType): its name, node
/// and StateNumber (as the MachineTool NodeSet numbers them).
fn program_state(run: &RunInfo) -> (&'static str, u32, u32) {
    match run.outcome {
        None => ("Running", ids::PROGRAM_RUNNING, 1),
        Some(Outcome::Done) => ("Ended", ids::PROGRAM_ENDED, 2),
        Some(Outcome::Error { .. } | Outcome::Aborted(_)) => ("Aborted", ids::PROGRAM_ABORTED, 4),
    }
}

/// A state machine's CurrentState and its Id.
fn current_state(text: &str, id: NodeId) -> (Variant, Variant) {
    (
        Variant::from(LocalizedText::new("", text)),
        Variant::from(id),
    )
}

impl Publisher {
    pub fn new(
        nodes: Nodes,
        manager: Arc<SimpleNodeManager>,
        subscriptions: Arc<SubscriptionCache>,
        history: Option<HistoryTarget>,
        machine: String,
    ) -> Self {
        Self {
            nodes,
            manager,
            subscriptions,
            history,
            machine,
            last: HashMap::new(),
        }
    }

    /// The state and results as they are now: (node, value) for every variable.
    fn snapshot(&mut self, shared: &Shared) -> (Vec<(NodeId, Variant)>, Option<RunInfo>) {
        let mut gateway = lock(shared);
        let service = &mut gateway.service;
        let passed = service.take_transitions();
        let v = *service.status();
        let (state, machine_ok) = (v.state, v.machine_ok);
        let run = service.run().cloned();
        let cycles = service.cycle_results().clone();
        let heartbeat = service.heartbeat();
        drop(gateway);
        // Each state the run passed through reaches a subscriber, in order, even when
        // it did not last until this look.
        let (state_id, code_id) = (
            self.nodes.state["RunState"].clone(),
            self.nodes.state["RunStateCode"].clone(),
        );
        for st in passed.iter().filter(|&&st| st != state) {
            self.write(vec![
                (state_id.clone(), Variant::from(st.name())),
                (code_id.clone(), Variant::from(*st as u16)),
            ]);
        }
        let s = |name: &str| self.nodes.state[name].clone();
        let ns = self.nodes.ns;
        let (item, item_id) = item_state(state, machine_ok);
        let (item, item_id) = current_state(item, ns.machinery(item_id));
        let ((mode, mode_id), operation_mode) = operation_mode(state);
        let (mode, mode_id) = current_state(mode, ns.machinery(mode_id));
        let mut out = vec![
            (s("ItemState"), item),
            (s("ItemStateId"), item_id),
            (s("OperationModeState"), mode),
            (s("OperationModeStateId"), mode_id),
            (
                s("OperationMode"),
                operation_mode.map_or(Variant::Empty, Variant::from),
            ),
            (s("MachineOk"), Variant::from(machine_ok)),
            (s("RunState"), Variant::from(state.name())),
            (s("RunStateCode"), Variant::from(state as u16)),
            (s("ProgressPermille"), Variant::from(v.progress_permille)),
            (s("Point"), Variant::from(v.point)),
            (s("ErrorKind"), Variant::from(v.error_kind)),
            (s("ErrorCode"), Variant::from(v.error_code)),
            (s("ResultsNotRecorded"), Variant::from(v.not_recorded)),
            (s("Heartbeat"), Variant::from(heartbeat)),
        ];
        if let Some(r) = &run {
            let (text, id, number) = program_state(r);
            let (program, program_id) = current_state(text, ns.machine_tool(id));
            out.extend([
                (s("Name"), Variant::from(format!("{:03}.h", r.program))),
                // The gateway keeps no production plan: its active program is the
                // only entry of its list, the first (0).
                (s("NumberInList"), Variant::from(0u16)),
                (s("Number"), Variant::from(r.program)),
                (s("ProgramState"), program),
                (s("ProgramStateId"), program_id),
                (s("ProgramStateNumber"), Variant::from(number)),
                (
                    s("StartedBy"),
                    Variant::from(match r.face {
                        Face::Plc => "plc",
                        Face::OpcUa => "opcua",
                    }),
                ),
                (s("StartTime"), date_time(r.started)),
                (s("EndTime"), r.ended.map_or(Variant::Empty, date_time)),
                (s("Cycle"), Variant::from(v.cycle)),
            ]);
        }
        for (cycle, nodes) in &self.nodes.cycles {
            let Some(res) = cycles.get(cycle) else {
                continue;
            };
            out.push((nodes.time.clone(), date_time(res.at)));
            // By the names the faces show, in their order.
            let named: BTreeMap<String, f64> = res
                .values
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect();
            let names: Vec<String> = named.keys().cloned().collect();
            let values: Vec<f64> = named.values().copied().collect();
            out.push((nodes.names.clone(), Variant::from(names)));
            out.push((nodes.values.clone(), Variant::from(values)));
            for (name, id) in &nodes.by_name {
                let value = named
                    .get(name)
                    .map_or(Variant::Empty, |&x| Variant::from(x));
                out.push((id.clone(), value));
            }
        }
        (out, run)
    }

    /// Writes what changed since the last call; the runs shown, when a run has ended
    /// since (`runs`: the history's last runs, newest first).
    fn write(&mut self, values: Vec<(NodeId, Variant)>) {
        let changed: Vec<(NodeId, Variant)> = values
            .into_iter()
            .filter(|(id, v)| self.last.get(id) != Some(v))
            .collect();
        if changed.is_empty() {
            return;
        }
        let now = DateTime::now();
        // The server's timestamp only: with a source timestamp the stack merges the
        // changes of one sampling interval into the last, and a subscriber would miss a
        // state that lasted less than that.
        let items: Vec<(NodeId, DataValue)> = changed
            .iter()
            .map(|(id, v)| {
                let dv = DataValue {
                    value: Some(v.clone()),
                    status: Some(opcua::types::StatusCode::Good),
                    server_timestamp: Some(now),
                    ..DataValue::null()
                };
                (id.clone(), dv)
            })
            .collect();
        if let Err(e) = self.manager.set_values(
            &self.subscriptions,
            items.iter().map(|(id, dv)| (id, None, dv.clone())),
        ) {
            tracing::error!("OPC UA face: cannot set the values: {e}");
            return;
        }
        self.last.extend(changed);
    }

    fn runs_values(&self, runs: &[RunRow]) -> Vec<(NodeId, Variant)> {
        let mut out = Vec::new();
        for (i, nodes) in self.nodes.runs.iter().enumerate() {
            let r = runs.get(i);
            for (name, _, _) in RUN_FIELDS {
                let value = match r {
                    None => Variant::Empty,
                    Some(r) => run_field(r, name),
                };
                out.push((nodes.fields[name].clone(), value));
            }
        }
        out
    }

    /// Runs until the service's announcements end (the service stops).
    pub async fn run(mut self, shared: Shared) {
        let mut changes = lock(&shared).service.watch();
        let mut ended_seen: Option<Option<SystemTime>> = None;
        loop {
            let (values, run) = self.snapshot(&shared);
            self.write(values);
            let ended = run.as_ref().map(|r| r.ended);
            // The history has a run's end before the core says it ended.
            if ended_seen != Some(ended.flatten()) && !self.nodes.runs.is_empty() {
                ended_seen = Some(ended.flatten());
                if let Some(runs) = self.last_runs().await {
                    let values = self.runs_values(&runs);
                    self.write(values);
                }
            }
            if changes.changed().await.is_err() {
                return;
            }
        }
    }

    async fn last_runs(&self) -> Option<Vec<RunRow>> {
        let target = self.history.clone()?;
        let (machine, n) = (self.machine.clone(), self.nodes.runs.len());
        let read = tokio::task::spawn_blocking(move || {
            let mut h = History::open(&target).map_err(|e| e.to_string())?;
            h.list(&Filter {
                machine: Some(machine),
                since: None,
            })
            .map_err(|e| e.to_string())
        })
        .await;
        match read {
            Ok(Ok(mut runs)) => {
                runs.sort_by_key(|r| std::cmp::Reverse(r.id));
                runs.truncate(n);
                Some(runs)
            }
            Ok(Err(e)) => {
                tracing::warn!("OPC UA face: cannot read the last runs: {e}");
                None
            }
            Err(e) => {
                tracing::warn!("OPC UA face: cannot read the last runs: {e}");
                None
            }
        }
    }
}

/// One field of a run of the history.
fn run_field(r: &RunRow, name: &str) -> Variant {
    match name {
        "Id" => Variant::from(r.id),
        "Status" => Variant::from(r.status.as_str()),
        "Source" => Variant::from(r.source.as_str()),
        "ProgramNumber" => r.program_number.map_or(Variant::Empty, Variant::from),
        "Program" => Variant::from(r.program.as_str()),
        "Started" => date_time_text(Some(&r.started)),
        "Finished" => date_time_text(r.finished.as_deref()),
        "Message" => r.message.as_deref().map_or(Variant::Empty, Variant::from),
        "Parameters" => Variant::from(r.parameters.clone()),
        "MachineTime" => r.machine_time_s.map_or(Variant::Empty, Variant::from),
        "ResultNames" | "ResultValues" => {
            let mut pairs: Vec<(String, f64)> = r
                .results
                .iter()
                .map(|x| (format!("{}.{}", x.cycle, x.name), x.value))
                .collect();
            for e in &r.iso_errors {
                let name = |when: fn(String) -> Quantity| when(e.name.clone()).to_string();
                pairs.push((name(Quantity::ErrorBefore), e.before));
                pairs.push((name(Quantity::ErrorAfter), e.after));
            }
            if name == "ResultNames" {
                Variant::from(pairs.into_iter().map(|p| p.0).collect::<Vec<_>>())
            } else {
                Variant::from(pairs.into_iter().map(|p| p.1).collect::<Vec<_>>())
            }
        }
        _ => Variant::Empty,
    }
}
