//! The rules every face's commands follow, without I/O: one measurement at a time, the
//! first start wins (a start while one runs or is being prepared is refused, never
//! queued), abort, acknowledge, progress and how a run ended. The faces (the PLC's
//! handshake, OPC UA's methods, the web face) do not keep these rules themselves: they
//! ask [`super::service::Service`], which keeps one `Measurement`.

use super::outcome::{Outcome, Refusal};

/// Which start an answer is for: counted from 1 by the service.
pub type StartId = u64;

/// How many REAL parameters a start carries (the PLC's request block, OPC UA's
/// StartProgram).
pub const START_PARAMS: usize = 8;

/// The face a measurement was started from: the PLC's heartbeat supervises only the
/// runs the PLC started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    Plc,
    OpcUa,
}

/// The sequence the result blocks carry for a run no PLC request started (OPC UA's
/// StartProgram), and from a start until its run ends. The PLC counts its requests
/// skipping 0 and the handshake takes no request with sequence 0, so it never equals
/// a PLC start's.
pub const NO_REQUEST: u16 = 0;

/// Who asked: the PLC with its request, or a face without a request block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// The PLC's request: the result blocks of its start carry its sequence.
    Plc { seq: u16 },
    /// OPC UA's methods: the result blocks carry [`NO_REQUEST`].
    OpcUa,
}

impl Origin {
    pub fn face(self) -> Face {
        match self {
            Origin::Plc { .. } => Face::Plc,
            Origin::OpcUa => Face::OpcUa,
        }
    }

    /// The sequence the result blocks carry for the run.
    pub fn results_seq(self) -> u16 {
        match self {
            Origin::Plc { seq } => seq,
            Origin::OpcUa => NO_REQUEST,
        }
    }
}

/// The measurement's state (the PLC's state register, OPC UA's RunState).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u16)]
pub enum State {
    #[default]
    Idle = 0,
    Busy = 1,
    Done = 2,
    Error = 3,
    Aborted = 4,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Idle => "idle",
            State::Busy => "busy",
            State::Done => "done",
            State::Error => "error",
            State::Aborted => "aborted",
        }
    }
}

/// What a face asks: the PLC's request codes 1, 2, 3, and OPC UA's methods.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    Start {
        program: u16,
        params: [f32; START_PARAMS],
        /// Go on where a cycle asks for confirmation.
        confirm: bool,
    },
    Abort,
    Acknowledge,
}

/// A start as the rules took it, from either face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Start {
    pub origin: Origin,
    pub program: u16,
    pub params: [f32; START_PARAMS],
    /// Go on where a cycle asks for confirmation.
    pub confirm: bool,
}

impl Start {
    pub fn face(&self) -> Face {
        self.origin.face()
    }
}

/// What the service must do after a command.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// A start passed the rules: the program, the machine's state and the history row
    /// are prepared off the gateway's lock (on the machine thread), and
    /// [`Measurement::prepared`] answers it. Meanwhile the start is "starting": other
    /// starts are refused as busy.
    Prepare(Start),
    Abort,
}

/// What every face shows of the measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Status {
    pub state: State,
    pub machine_ok: bool,
    /// Ends of runs wait in the spool, not yet in the history.
    pub not_recorded: bool,
    /// Who started the running (or last) measurement; none before the first.
    pub origin: Option<Origin>,
    pub program: u16,
    pub progress_permille: u16,
    pub point: u16,
    pub error_kind: u16,
    pub error_code: u16,
    /// The cycle whose results the last run that ended done left (0 otherwise).
    pub cycle: u16,
}

impl Status {
    /// A start would not be refused for the state (the PLC's "ready" bit).
    pub fn ready(&self) -> bool {
        self.machine_ok && self.state != State::Busy && self.state != State::Error
    }

    /// The results of the last run are valid (it ended done).
    pub fn results_valid(&self) -> bool {
        self.state == State::Done
    }
}

#[derive(Debug, Default)]
pub struct Measurement {
    status: Status,
    /// The start being prepared (off the gateway's lock), not yet answered.
    starting: Option<Start>,
}

impl Measurement {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn status(&self) -> &Status {
        &self.status
    }

    pub fn state(&self) -> State {
        self.status.state
    }

    pub fn set_machine_ok(&mut self, ok: bool) {
        self.status.machine_ok = ok;
    }

    /// Whether ends of runs wait in the spool (the "results not yet recorded" bit).
    pub fn set_not_recorded(&mut self, pending: bool) {
        self.status.not_recorded = pending;
    }

    /// The start being prepared, if one is.
    pub fn starting(&self) -> Option<&Start> {
        self.starting.as_ref()
    }

    /// No measurement runs and none is being prepared.
    pub fn between_measurements(&self) -> bool {
        self.status.state != State::Busy && self.starting.is_none()
    }

    /// A command of any face. `well_formed`: the face found nothing wrong in how it was
    /// asked (the PLC's flags have no unknown bits); a parameter that is not a finite
    /// number is refused here for every face.
    pub fn decide(
        &mut self,
        cmd: Command,
        origin: Origin,
        well_formed: bool,
    ) -> Result<Option<Action>, Refusal> {
        let busy = !self.between_measurements();
        match cmd {
            Command::Start { .. } if busy => Err(Refusal::Busy),
            Command::Start { .. } if self.status.state == State::Error => {
                Err(Refusal::ErrorPending)
            }
            Command::Start { .. } if !self.status.machine_ok => Err(Refusal::MachineNotReady),
            Command::Start { params, .. }
                if !well_formed || params.iter().any(|p| !p.is_finite()) =>
            {
                Err(Refusal::BadRequest)
            }
            Command::Start {
                program,
                params,
                confirm,
            } => {
                let start = Start {
                    origin,
                    program,
                    params,
                    confirm,
                };
                self.starting = Some(start);
                Ok(Some(Action::Prepare(start)))
            }
            Command::Abort if busy => Ok(Some(Action::Abort)),
            Command::Abort => Err(Refusal::NotBusy),
            Command::Acknowledge if busy => Err(Refusal::Busy),
            Command::Acknowledge => {
                self.status.state = State::Idle;
                self.status.error_kind = 0;
                self.status.error_code = 0;
                Ok(None)
            }
        }
    }

    /// The start being prepared is taken (`Ok`: the state is busy) or refused. `None`
    /// for a start that is not the one being prepared (nothing changes), else whether
    /// the run is now under way.
    pub fn prepared(&mut self, start: &Start, answer: Result<(), Refusal>) -> Option<bool> {
        if self.starting.as_ref() != Some(start) {
            return None;
        }
        self.starting = None;
        if answer.is_ok() {
            let s = &mut self.status;
            s.state = State::Busy;
            s.origin = Some(start.origin);
            s.program = start.program;
            s.progress_permille = 0;
            s.point = 0;
            s.error_kind = 0;
            s.error_code = 0;
            s.cycle = 0;
        }
        Some(answer.is_ok())
    }

    /// Progress of the running measurement.
    pub fn progress(&mut self, permille: u16, point: u16) {
        if self.status.state == State::Busy {
            self.status.progress_permille = permille.min(1000);
            self.status.point = point;
        }
    }

    /// The run ended; returns the sequence its results belong to.
    pub fn finish(&mut self, outcome: Outcome, cycle: u16) -> u16 {
        let s = &mut self.status;
        s.cycle = if outcome == Outcome::Done { cycle } else { 0 };
        match outcome {
            Outcome::Done => {
                s.state = State::Done;
                s.progress_permille = 1000;
            }
            Outcome::Error { kind, code } => {
                s.state = State::Error;
                s.error_kind = kind;
                s.error_code = code;
            }
            Outcome::Aborted(r) => {
                s.state = State::Aborted;
                s.error_kind = r.error_kind();
            }
        }
        s.origin.map_or(NO_REQUEST, Origin::results_seq)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::outcome::{AbortReason, ERROR_KIND_PLC_HEARTBEAT};

    fn start_cmd(params: [f32; START_PARAMS], confirm: bool) -> Command {
        Command::Start {
            program: 431,
            params,
            confirm,
        }
    }

    fn ready() -> Measurement {
        let mut m = Measurement::new();
        m.set_machine_ok(true);
        m
    }

    #[test]
    fn the_first_start_wins_and_a_second_is_refused_while_prepared_or_running() {
        let mut m = ready();
        let a = m.decide(start_cmd([0.0; 8], true), Origin::OpcUa, true);
        let Ok(Some(Action::Prepare(start))) = a else {
            panic!("{a:?}")
        };
        assert_eq!((start.origin, start.confirm), (Origin::OpcUa, true));
        let plc = Origin::Plc { seq: 3 };
        assert_eq!(
            m.decide(start_cmd([0.0; 8], false), plc, true),
            Err(Refusal::Busy)
        );
        // An abort while it is prepared is taken.
        assert_eq!(m.decide(Command::Abort, plc, true), Ok(Some(Action::Abort)));
        assert_eq!(m.prepared(&start, Ok(())), Some(true));
        assert_eq!(m.state(), State::Busy);
        assert_eq!(m.status().origin, Some(Origin::OpcUa));
        assert_eq!(
            m.decide(start_cmd([0.0; 8], false), plc, true),
            Err(Refusal::Busy)
        );
        assert_eq!(
            m.decide(Command::Acknowledge, plc, true),
            Err(Refusal::Busy)
        );
        // Its results carry no PLC request's sequence.
        assert_eq!(m.finish(Outcome::Done, 431), NO_REQUEST);
        assert!(m.status().results_valid());
        assert_eq!(m.status().cycle, 431);
    }

    #[test]
    fn a_start_refused_when_prepared_leaves_the_last_runs_state() {
        let mut m = ready();
        let Ok(Some(Action::Prepare(s))) =
            m.decide(start_cmd([0.0; 8], false), Origin::Plc { seq: 1 }, true)
        else {
            panic!()
        };
        m.prepared(&s, Ok(()));
        assert_eq!(m.finish(Outcome::Done, 431), 1);
        let Ok(Some(Action::Prepare(s2))) =
            m.decide(start_cmd([0.0; 8], false), Origin::Plc { seq: 2 }, true)
        else {
            panic!()
        };
        assert_eq!(
            m.prepared(&s2, Err(Refusal::HistoryUnavailable)),
            Some(false)
        );
        assert_eq!(m.state(), State::Done, "the last run's state stays");
        assert!(m.starting().is_none());
        // An answer for a start that is not being prepared changes nothing.
        assert_eq!(m.prepared(&s2, Ok(())), None);
        assert_eq!(m.state(), State::Done);
    }

    #[test]
    fn an_error_must_be_acknowledged_before_the_next_start() {
        let mut m = ready();
        let plc = Origin::Plc { seq: 1 };
        let Ok(Some(Action::Prepare(s))) = m.decide(start_cmd([0.0; 8], false), plc, true) else {
            panic!()
        };
        m.prepared(&s, Ok(()));
        m.finish(Outcome::Error { kind: 1, code: 7 }, 0);
        assert!(!m.status().ready());
        assert_eq!(
            m.decide(start_cmd([0.0; 8], false), plc, true),
            Err(Refusal::ErrorPending)
        );
        assert_eq!(m.decide(Command::Abort, plc, true), Err(Refusal::NotBusy));
        assert_eq!(m.decide(Command::Acknowledge, plc, true), Ok(None));
        assert_eq!((m.state(), m.status().error_kind), (State::Idle, 0));
        assert!(m.status().ready());
    }

    #[test]
    fn bad_parameters_and_a_machine_not_up_are_refused_for_every_face() {
        let mut m = Measurement::new();
        for origin in [Origin::OpcUa, Origin::Plc { seq: 9 }] {
            assert_eq!(
                m.decide(start_cmd([0.0; 8], false), origin, true),
                Err(Refusal::MachineNotReady)
            );
        }
        m.set_machine_ok(true);
        let mut nan = [0.0; 8];
        nan[2] = f32::INFINITY;
        for origin in [Origin::OpcUa, Origin::Plc { seq: 9 }] {
            assert_eq!(
                m.decide(start_cmd(nan, false), origin, true),
                Err(Refusal::BadRequest)
            );
            assert_eq!(
                m.decide(start_cmd([0.0; 8], false), origin, false),
                Err(Refusal::BadRequest)
            );
        }
        assert!(m.starting().is_none());
    }

    #[test]
    fn an_aborted_run_says_why_and_progress_counts_only_while_busy() {
        let mut m = ready();
        m.progress(500, 3);
        assert_eq!(m.status().progress_permille, 0);
        let Ok(Some(Action::Prepare(s))) =
            m.decide(start_cmd([0.0; 8], false), Origin::Plc { seq: 4 }, true)
        else {
            panic!()
        };
        m.prepared(&s, Ok(()));
        m.progress(5000, 3);
        assert_eq!((m.status().progress_permille, m.status().point), (1000, 3));
        assert_eq!(
            m.finish(Outcome::Aborted(AbortReason::PlcHeartbeat), 431),
            4
        );
        assert_eq!(m.status().error_kind, ERROR_KIND_PLC_HEARTBEAT);
        assert_eq!((m.state(), m.status().cycle), (State::Aborted, 0));
    }
}
