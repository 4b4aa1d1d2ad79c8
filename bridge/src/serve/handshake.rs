//! The level-based handshake with the PLC, without I/O: a change of the request
//! sequence triggers the request code once; the gateway answers by echoing the
//! sequence and the code (bit 15 set: refused, with a reason). One measurement at a
//! time: a start while busy is refused, never queued.

use super::register_map::{Request, StateView, FLAGS_KNOWN};
use std::time::{Duration, Instant};

pub use super::outcome::{
    machine_error_kind, AbortReason, Outcome, Refusal, ERROR_KIND_ABORT_REQUEST, ERROR_KIND_CYCLE,
    ERROR_KIND_NOT_KEPT, ERROR_KIND_PLC_HEARTBEAT, ERROR_KIND_PROGRAM, ERROR_KIND_SHUTDOWN,
};

pub const CODE_START: u16 = 1;
pub const CODE_ABORT: u16 = 2;
pub const CODE_ACKNOWLEDGE: u16 = 3;
pub const REFUSED: u16 = 0x8000;

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

/// Who asked for a start: the PLC with its request, or a face without a request block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// The PLC's start request: the result blocks carry its sequence.
    Plc { seq: u16 },
    /// OPC UA's StartProgram: the result blocks carry [`NO_REQUEST`].
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

/// The state register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum State {
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

/// Bits of the bits register.
pub const BIT_READY: u16 = 1 << 0;
pub const BIT_BUSY: u16 = 1 << 1;
pub const BIT_DONE: u16 = 1 << 2;
pub const BIT_ERROR: u16 = 1 << 3;
pub const BIT_MACHINE_OK: u16 = 1 << 4;
pub const BIT_RESULTS_VALID: u16 = 1 << 5;
/// Ends of runs are in the spool, not yet in the history.
pub const BIT_NOT_RECORDED: u16 = 1 << 6;

/// What the gateway must do after a request.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// A start passed the handshake's checks: the program, the machine's state and the
    /// history row are prepared off the faces' lock (on the machine thread), and
    /// [`Handshake::prepared`] answers it. Meanwhile the start is "starting": other
    /// starts are refused as busy, and the PLC's acknowledge registers wait.
    Prepare(Start),
    Abort,
}

/// What a face asks: the PLC's request codes 1, 2, 3, and OPC UA's methods.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    Start {
        program: u16,
        params: [f32; super::register_map::REQ_PARAM_COUNT],
        /// Go on where a cycle asks for confirmation.
        confirm: bool,
    },
    Abort,
    Acknowledge,
}

/// A start as the handshake took it, from either face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Start {
    pub origin: Origin,
    pub program: u16,
    pub params: [f32; super::register_map::REQ_PARAM_COUNT],
    /// Go on where a cycle asks for confirmation.
    pub confirm: bool,
}

impl Start {
    pub fn face(&self) -> Face {
        self.origin.face()
    }
}

#[derive(Debug)]
pub struct Handshake {
    last_seq: u16,
    view: StateView,
    state: State,
    machine_ok: bool,
    not_recorded: bool,
    /// Who started the running (or last) measurement; none before the first.
    busy: Option<Origin>,
    /// The start being prepared (off the faces' lock), not yet answered.
    starting: Option<Start>,
    plc_heartbeat: u16,
    heartbeat_seen: Instant,
    heartbeat_timeout: Option<Duration>,
}

impl Handshake {
    pub fn new(heartbeat_timeout: Option<Duration>, now: Instant) -> Self {
        let mut h = Self {
            last_seq: 0,
            view: StateView::default(),
            state: State::Idle,
            machine_ok: false,
            not_recorded: false,
            busy: None,
            starting: None,
            plc_heartbeat: 0,
            heartbeat_seen: now,
            heartbeat_timeout,
        };
        h.refresh_bits();
        h
    }

    pub fn state(&self) -> State {
        self.state
    }

    pub fn view(&self) -> &StateView {
        &self.view
    }

    pub fn machine_ok(&self) -> bool {
        self.machine_ok
    }

    pub fn set_machine_ok(&mut self, ok: bool) {
        self.machine_ok = ok;
        self.refresh_bits();
    }

    /// Whether ends of runs wait in the spool (the "results not yet recorded" bit).
    pub fn set_not_recorded(&mut self, pending: bool) {
        if self.not_recorded != pending {
            self.not_recorded = pending;
            self.refresh_bits();
        }
    }

    fn refresh_bits(&mut self) {
        let mut b = 0;
        let s = self.state;
        if self.machine_ok && s != State::Busy && s != State::Error {
            b |= BIT_READY;
        }
        match s {
            State::Busy => b |= BIT_BUSY,
            State::Done => b |= BIT_DONE | BIT_RESULTS_VALID,
            State::Error => b |= BIT_ERROR,
            State::Idle | State::Aborted => {}
        }
        if self.machine_ok {
            b |= BIT_MACHINE_OK;
        }
        if self.not_recorded {
            b |= BIT_NOT_RECORDED;
        }
        self.view.state = s as u16;
        self.view.bits = b;
    }

    /// Looks at the request block: a new sequence runs its code. Returns what the
    /// gateway must do. A start that passes the checks here is acknowledged only once
    /// it is prepared ([`Handshake::prepared`]): the PLC waits for register 32.
    pub fn on_request(&mut self, req: &Request, now: Instant) -> Option<Action> {
        if req.plc_heartbeat != self.plc_heartbeat {
            self.plc_heartbeat = req.plc_heartbeat;
            self.heartbeat_seen = now;
        }
        if req.seq == NO_REQUEST || req.seq == self.last_seq {
            return None;
        }
        self.last_seq = req.seq;
        let origin = Origin::Plc { seq: req.seq };
        let answer = match req.code {
            CODE_START => {
                let cmd = Command::Start {
                    program: req.program,
                    params: req.params,
                    confirm: req.flags & super::register_map::FLAG_CONFIRM != 0,
                };
                self.decide(cmd, origin, req.flags & !FLAGS_KNOWN == 0)
            }
            CODE_ABORT => self.decide(Command::Abort, origin, true),
            CODE_ACKNOWLEDGE => self.decide(Command::Acknowledge, origin, true),
            _ => Err(Refusal::UnknownCode),
        };
        match &answer {
            Ok(Some(Action::Prepare(_))) => {}
            Ok(_) => self.acknowledge(req.seq, req.code, Ok(())),
            Err(r) => self.acknowledge(req.seq, req.code, Err(*r)),
        }
        self.refresh_bits();
        answer.ok().flatten()
    }

    fn acknowledge(&mut self, seq: u16, code: u16, answer: Result<(), Refusal>) {
        self.view.ack_seq = seq;
        match answer {
            Ok(()) => {
                self.view.ack_code = code;
                self.view.reason = 0;
            }
            Err(r) => {
                self.view.ack_code = code | REFUSED;
                self.view.reason = r as u16;
            }
        }
    }

    /// A command of OPC UA's methods (a face without a request block): decided by the
    /// same rules as the PLC's requests, answered to the caller; the PLC's acknowledge
    /// registers stay the PLC's. A run started so has the result sequence
    /// [`NO_REQUEST`], which no PLC start has.
    pub fn command(&mut self, cmd: Command) -> Result<Option<Action>, Refusal> {
        let answer = self.decide(cmd, Origin::OpcUa, true);
        self.refresh_bits();
        answer
    }

    /// The start being prepared is taken (`Ok`: the state is busy) or refused; the
    /// PLC's start is acknowledged now, unless the PLC has sent a newer request since.
    /// Whether the run is now under way (not for a start that is not the one being
    /// prepared).
    pub fn prepared(&mut self, start: &Start, answer: Result<(), Refusal>, now: Instant) -> bool {
        if self.starting.as_ref() != Some(start) {
            return false;
        }
        self.starting = None;
        match start.origin {
            Origin::Plc { seq } if self.last_seq == seq => {
                self.acknowledge(seq, CODE_START, answer);
            }
            _ => {}
        }
        if answer.is_ok() {
            self.begin(start, now);
        }
        self.refresh_bits();
        answer.is_ok()
    }

    /// The start being prepared, if one is.
    pub fn starting(&self) -> Option<&Start> {
        self.starting.as_ref()
    }

    fn begin(&mut self, start: &Start, now: Instant) {
        self.state = State::Busy;
        self.busy = Some(start.origin);
        self.heartbeat_seen = now;
        self.view.program = start.program;
        self.view.progress_permille = 0;
        self.view.point = 0;
        self.view.error_kind = 0;
        self.view.error_code = 0;
        self.view.cycle = 0;
    }

    /// The face the running (or last) measurement was started from.
    pub fn busy_face(&self) -> Option<Face> {
        self.busy.map(Origin::face)
    }

    /// One measurement at a time, the first start wins: a start while one runs or is
    /// being prepared is refused as busy, never queued. `seq`: the sequence a start's
    /// results carry; `flags_known`: the request's flags have no unknown bits.
    fn decide(
        &mut self,
        cmd: Command,
        origin: Origin,
        flags_known: bool,
    ) -> Result<Option<Action>, Refusal> {
        let busy = self.state == State::Busy || self.starting.is_some();
        match cmd {
            Command::Start { .. } if busy => Err(Refusal::Busy),
            Command::Start { .. } if self.state == State::Error => Err(Refusal::ErrorPending),
            Command::Start { .. } if !self.machine_ok => Err(Refusal::MachineNotReady),
            Command::Start { params, .. }
                if !flags_known || params.iter().any(|p| !p.is_finite()) =>
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
                self.state = State::Idle;
                self.view.error_kind = 0;
                self.view.error_code = 0;
                Ok(None)
            }
        }
    }

    /// Progress of the running measurement.
    pub fn progress(&mut self, permille: u16, point: u16) {
        if self.state == State::Busy {
            self.view.progress_permille = permille.min(1000);
            self.view.point = point;
        }
    }

    /// The run ended; returns the sequence its results belong to.
    pub fn finish(&mut self, outcome: Outcome, cycle: u16) -> u16 {
        self.view.cycle = if outcome == Outcome::Done { cycle } else { 0 };
        match outcome {
            Outcome::Done => {
                self.state = State::Done;
                self.view.progress_permille = 1000;
            }
            Outcome::Error { kind, code } => {
                self.state = State::Error;
                self.view.error_kind = kind;
                self.view.error_code = code;
            }
            Outcome::Aborted(r) => {
                self.state = State::Aborted;
                self.view.error_kind = r.error_kind();
            }
        }
        self.refresh_bits();
        self.busy.map_or(NO_REQUEST, Origin::results_seq)
    }

    /// Is the PLC heartbeat stale while busy (the motion must be aborted)?
    pub fn heartbeat_lost(&self, now: Instant) -> bool {
        match self.heartbeat_timeout {
            Some(t) => {
                self.state == State::Busy
                    && matches!(self.busy, Some(Origin::Plc { .. }))
                    && now.duration_since(self.heartbeat_seen) > t
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(code: u16, seq: u16, hb: u16) -> Request {
        Request {
            code,
            seq,
            program: 431,
            flags: 0,
            params: [0.0; 8],
            plc_heartbeat: hb,
        }
    }

    fn start_cmd(params: [f32; 8], confirm: bool) -> Command {
        Command::Start {
            program: 431,
            params,
            confirm,
        }
    }

    fn ready() -> (Handshake, Instant) {
        let now = Instant::now();
        let mut h = Handshake::new(Some(Duration::from_secs(1)), now);
        h.set_machine_ok(true);
        (h, now)
    }

    /// The PLC's request, and a start prepared with `answer`: what the gateway does.
    fn request(
        h: &mut Handshake,
        r: &Request,
        now: Instant,
        answer: Result<(), Refusal>,
    ) -> Option<Action> {
        let action = h.on_request(r, now);
        if let Some(Action::Prepare(start)) = &action {
            h.prepared(start, answer, now);
        }
        action
    }

    #[test]
    fn start_runs_once_per_sequence_and_refuses_while_busy() {
        let (mut h, now) = ready();
        let a = h.on_request(&req(CODE_START, 1, 0), now);
        let Some(Action::Prepare(start)) = a else {
            panic!("{a:?}")
        };
        assert_eq!(
            (start.origin, start.program, start.confirm),
            (Origin::Plc { seq: 1 }, 431, false)
        );
        // Being prepared: not yet acknowledged, another start is busy.
        assert_eq!(h.view().ack_seq, 0);
        assert_eq!(h.starting(), Some(&start));
        assert_eq!(h.command(start_cmd([0.0; 8], false)), Err(Refusal::Busy));
        h.prepared(&start, Ok(()), now);
        assert_eq!((h.view().ack_seq, h.view().ack_code), (1, CODE_START));
        assert_eq!(h.view().bits & BIT_BUSY, BIT_BUSY);
        // The same level again: nothing.
        assert_eq!(h.on_request(&req(CODE_START, 1, 0), now), None);
        // A new start while busy: refused, never queued.
        assert_eq!(h.on_request(&req(CODE_START, 2, 0), now), None);
        assert_eq!(h.view().ack_seq, 2);
        assert_eq!(h.view().ack_code, CODE_START | REFUSED);
        assert_eq!(h.view().reason, Refusal::Busy as u16);
        assert_eq!(h.finish(Outcome::Done, 431), 1);
        assert_eq!(h.state(), State::Done);
        assert_eq!(h.view().bits & BIT_RESULTS_VALID, BIT_RESULTS_VALID);
    }

    #[test]
    fn a_start_refused_while_prepared_is_acknowledged_refused_and_nothing_runs() {
        let (mut h, now) = ready();
        request(&mut h, &req(CODE_START, 1, 0), now, Ok(()));
        h.finish(Outcome::Done, 431);
        request(
            &mut h,
            &req(CODE_START, 2, 0),
            now,
            Err(Refusal::HistoryUnavailable),
        );
        assert_eq!(h.view().ack_seq, 2);
        assert_eq!(h.view().ack_code, CODE_START | REFUSED);
        assert_eq!(h.view().reason, Refusal::HistoryUnavailable as u16);
        assert_eq!(h.state(), State::Done, "the last run's state stays");
        assert_eq!(h.starting(), None);
        // An abort while a start is prepared is taken; a newer request of the PLC
        // keeps its own acknowledge when the start is answered after it.
        let Some(Action::Prepare(start)) = h.on_request(&req(CODE_START, 3, 0), now) else {
            panic!()
        };
        assert_eq!(
            h.on_request(&req(CODE_ABORT, 4, 0), now),
            Some(Action::Abort)
        );
        h.prepared(&start, Ok(()), now);
        assert_eq!((h.view().ack_seq, h.view().ack_code), (4, CODE_ABORT));
        assert_eq!(h.state(), State::Busy);
    }

    #[test]
    fn error_must_be_acknowledged_before_the_next_start() {
        let (mut h, now) = ready();
        request(&mut h, &req(CODE_START, 1, 0), now, Ok(()));
        h.finish(Outcome::Error { kind: 1, code: 0 }, 0);
        assert_eq!(h.on_request(&req(CODE_START, 2, 0), now), None);
        assert_eq!(h.view().reason, Refusal::ErrorPending as u16);
        assert_eq!(h.on_request(&req(CODE_ACKNOWLEDGE, 3, 0), now), None);
        assert_eq!(h.view().ack_code, CODE_ACKNOWLEDGE);
        assert_eq!(h.state(), State::Idle);
        assert_eq!(h.view().error_kind, 0);
        assert!(h.on_request(&req(CODE_START, 4, 0), now).is_some());
    }

    #[test]
    fn refusals_go_into_the_acknowledge_code() {
        let (mut h, now) = ready();
        request(
            &mut h,
            &req(CODE_START, 1, 0),
            now,
            Err(Refusal::UnknownProgram),
        );
        assert_eq!(h.view().reason, Refusal::UnknownProgram as u16);
        assert_eq!(h.state(), State::Idle);
        h.on_request(&req(CODE_ABORT, 2, 0), now);
        assert_eq!(h.view().reason, Refusal::NotBusy as u16);
        h.on_request(&req(9, 3, 0), now);
        assert_eq!(h.view().ack_code, 9 | REFUSED);
        assert_eq!(h.view().reason, Refusal::UnknownCode as u16);
        let mut bad = req(CODE_START, 4, 0);
        bad.params[3] = f32::NAN;
        h.on_request(&bad, now);
        assert_eq!(h.view().reason, Refusal::BadRequest as u16);
    }

    #[test]
    fn a_command_follows_the_same_rules_and_leaves_the_plc_acknowledge_alone() {
        let (mut h, now) = ready();
        h.on_request(&req(CODE_ACKNOWLEDGE, 7, 0), now);
        let before = h.view().clone();
        let a = h.command(start_cmd([0.0; 8], true));
        let Ok(Some(Action::Prepare(start))) = a else {
            panic!("{a:?}")
        };
        assert_eq!((start.origin, start.confirm), (Origin::OpcUa, true));
        h.prepared(&start, Ok(()), now);
        assert_eq!(h.state(), State::Busy);
        assert_eq!(h.busy_face(), Some(Face::OpcUa));
        assert_eq!(
            (h.view().ack_seq, h.view().ack_code, h.view().reason),
            (before.ack_seq, before.ack_code, before.reason)
        );
        // The PLC's start while it runs: busy, in the PLC's registers.
        h.on_request(&req(CODE_START, 8, 0), now);
        assert_eq!(h.view().reason, Refusal::Busy as u16);
        // A second start of the face: busy, to the caller.
        assert_eq!(h.command(start_cmd([0.0; 8], false)), Err(Refusal::Busy));
        // The PLC's heartbeat does not supervise the face's run.
        assert!(!h.heartbeat_lost(now + Duration::from_secs(5)));
        assert_eq!(h.command(Command::Abort), Ok(Some(Action::Abort)));
        // Its results carry no PLC request's sequence.
        assert_eq!(
            h.finish(Outcome::Aborted(AbortReason::Request), 0),
            NO_REQUEST
        );
        assert_eq!(h.command(Command::Abort), Err(Refusal::NotBusy));
        let mut nan = [0.0; 8];
        nan[2] = f32::INFINITY;
        assert_eq!(h.command(start_cmd(nan, false)), Err(Refusal::BadRequest));
    }

    #[test]
    fn a_request_with_sequence_0_is_not_taken_and_a_plc_run_carries_its_own() {
        let (mut h, now) = ready();
        request(&mut h, &req(CODE_START, 5, 0), now, Ok(()));
        assert_eq!(h.finish(Outcome::Done, 431), 5);
        h.on_request(&req(CODE_ACKNOWLEDGE, 6, 0), now);
        let before = h.view().clone();
        // 0 is the sequence of runs no PLC request started: a start with it is not
        // taken, and the next request counts as new.
        assert_eq!(h.on_request(&req(CODE_START, 0, 0), now), None);
        assert_eq!(h.view(), &before);
        assert!(h.starting().is_none());
        let a = h.on_request(&req(CODE_START, 7, 0), now);
        assert!(matches!(a, Some(Action::Prepare(_))), "{a:?}");
    }

    #[test]
    fn stale_heartbeat_while_busy_is_lost() {
        let (mut h, now) = ready();
        assert!(
            !h.heartbeat_lost(now + Duration::from_secs(5)),
            "idle: no check"
        );
        request(&mut h, &req(CODE_START, 1, 0), now, Ok(()));
        let later = now + Duration::from_millis(900);
        h.on_request(&req(CODE_START, 1, 1), later);
        assert!(!h.heartbeat_lost(later + Duration::from_millis(900)));
        assert!(h.heartbeat_lost(later + Duration::from_millis(1100)));
        h.finish(Outcome::Aborted(AbortReason::PlcHeartbeat), 0);
        assert_eq!(h.view().error_kind, ERROR_KIND_PLC_HEARTBEAT);
        assert_eq!(h.state(), State::Aborted);
    }
}
