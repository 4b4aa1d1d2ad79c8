//! The level-based handshake with the PLC, without I/O: a change of the request
//! sequence triggers the request code once; the gateway answers by echoing the
//! sequence and the code (bit 15 set: refused, with a reason). One measurement at a
//! time: a start while busy is refused, never queued.

use super::register_map::{Request, StateView, FLAGS_KNOWN};
use std::time::{Duration, Instant};

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

/// Why a request was refused (the reason register).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Refusal {
    /// A measurement is running.
    Busy = 1,
    /// The request code is none of start, abort, acknowledge.
    UnknownCode = 2,
    /// No program NNN.h in the program folder.
    UnknownProgram = 3,
    /// The program does not parse or does not fit the machine (nothing moved).
    InvalidProgram = 4,
    /// The last run ended in an error: acknowledge it first.
    ErrorPending = 5,
    /// Abort without a running measurement.
    NotBusy = 6,
    /// Flags with unknown bits, or a parameter that is not a finite number.
    BadRequest = 7,
    /// The machine is not up.
    MachineNotReady = 8,
    /// The run's `running` row could not be written (nothing moved).
    HistoryUnavailable = 9,
}

impl Refusal {
    /// The reason in words, as the README's reason table says it.
    pub fn describe(self) -> &'static str {
        match self {
            Refusal::Busy => "a measurement is running",
            Refusal::UnknownCode => "unknown request code",
            Refusal::UnknownProgram => "no such program in the program folder",
            Refusal::InvalidProgram => "the program does not parse or does not fit the machine",
            Refusal::ErrorPending => "the last run ended in an error: acknowledge it first",
            Refusal::NotBusy => "no measurement is running",
            Refusal::BadRequest => "a parameter is not a finite number",
            Refusal::MachineNotReady => "the machine is not up",
            Refusal::HistoryUnavailable => "the run could not be recorded in the history",
        }
    }
}

/// Why a running measurement was aborted (the error kind register).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum AbortReason {
    Request = 1,
    PlcHeartbeat = 2,
    Shutdown = 3,
}

impl AbortReason {
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            1 => Some(Self::Request),
            2 => Some(Self::PlcHeartbeat),
            3 => Some(Self::Shutdown),
            _ => None,
        }
    }
    pub fn describe(self) -> &'static str {
        match self {
            AbortReason::Request => "abort requested by the PLC",
            AbortReason::PlcHeartbeat => "PLC heartbeat lost",
            AbortReason::Shutdown => "gateway shutting down",
        }
    }
    /// The error kind register value.
    pub fn error_kind(self) -> u16 {
        match self {
            AbortReason::Request => ERROR_KIND_ABORT_REQUEST,
            AbortReason::PlcHeartbeat => ERROR_KIND_PLC_HEARTBEAT,
            AbortReason::Shutdown => ERROR_KIND_SHUTDOWN,
        }
    }
}

/// Error kind register values: 1..=10 are the machine's `hal::ErrorKind`s (see
/// [`machine_error_kind`]), these are the gateway's.
pub const ERROR_KIND_ABORT_REQUEST: u16 = 20;
pub const ERROR_KIND_PLC_HEARTBEAT: u16 = 21;
pub const ERROR_KIND_SHUTDOWN: u16 = 22;
/// The run ended but its end could be kept neither in the history nor in the spool:
/// its results are not shown.
pub const ERROR_KIND_NOT_KEPT: u16 = 23;
/// A cycle failed without a machine error (its own checks, tolerance stop, Q309).
pub const ERROR_KIND_CYCLE: u16 = 30;
/// The program stopped itself with `FN 14: ERROR = n`; the error code register holds n.
pub const ERROR_KIND_PROGRAM: u16 = 31;

pub fn machine_error_kind(k: hal::ErrorKind) -> u16 {
    use hal::ErrorKind::*;
    match k {
        NotTriggered => 1,
        AlreadyDeflected => 2,
        ProbeCollision => 3,
        DriveFault => 4,
        NodeLost => 5,
        Timeout => 6,
        SoftwareLimit => 7,
        Bus => 8,
        InvalidRequest => 9,
        _ => 10,
    }
}

/// What the gateway must do after a request.
#[derive(Clone, Debug, PartialEq)]
pub enum Action<P> {
    Start { seq: u16, program: P, confirm: bool },
    Abort,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Done,
    Error { kind: u16, code: u16 },
    Aborted(AbortReason),
}

#[derive(Debug)]
pub struct Handshake {
    last_seq: u16,
    view: StateView,
    state: State,
    machine_ok: bool,
    not_recorded: bool,
    busy_seq: u16,
    busy_face: Face,
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
            busy_seq: 0,
            busy_face: Face::Plc,
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

    /// Looks at the request block: a new sequence runs its code. `resolve` finds the
    /// program of a start (or says why not). Returns what the gateway must do.
    pub fn on_request<P>(
        &mut self,
        req: &Request,
        now: Instant,
        resolve: impl FnOnce(u16) -> Result<P, Refusal>,
    ) -> Option<Action<P>> {
        if req.plc_heartbeat != self.plc_heartbeat {
            self.plc_heartbeat = req.plc_heartbeat;
            self.heartbeat_seen = now;
        }
        if req.seq == self.last_seq {
            return None;
        }
        self.last_seq = req.seq;
        let (answer, action) = self.decide(req, resolve);
        self.view.ack_seq = req.seq;
        match answer {
            Ok(()) => {
                self.view.ack_code = req.code;
                self.view.reason = 0;
            }
            Err(r) => {
                self.view.ack_code = req.code | REFUSED;
                self.view.reason = r as u16;
            }
        }
        if let Some(Action::Start { seq, .. }) = &action {
            self.begin(*seq, req.program, Face::Plc, now);
        }
        self.refresh_bits();
        action
    }

    /// A command of a face that has no request block (OPC UA's methods): decided by
    /// the same rules as the PLC's requests, answered to the caller; the PLC's
    /// acknowledge registers stay the PLC's. A run started so has a result sequence
    /// the PLC's current request does not have, so its results never pass for the
    /// PLC's own.
    pub fn command<P>(
        &mut self,
        code: u16,
        program: u16,
        params: [f32; super::register_map::REQ_PARAM_COUNT],
        confirm: bool,
        now: Instant,
        resolve: impl FnOnce(u16) -> Result<P, Refusal>,
    ) -> Result<Option<Action<P>>, Refusal> {
        let req = Request {
            code,
            seq: self.last_seq.wrapping_sub(1),
            program,
            flags: if confirm {
                super::register_map::FLAG_CONFIRM
            } else {
                0
            },
            params,
            plc_heartbeat: self.plc_heartbeat,
        };
        let (answer, action) = self.decide(&req, resolve);
        if let Some(Action::Start { seq, .. }) = &action {
            self.begin(*seq, program, Face::OpcUa, now);
        }
        self.refresh_bits();
        answer.map(|()| action)
    }

    fn begin(&mut self, seq: u16, program: u16, face: Face, now: Instant) {
        self.state = State::Busy;
        self.busy_seq = seq;
        self.busy_face = face;
        self.heartbeat_seen = now;
        self.view.program = program;
        self.view.progress_permille = 0;
        self.view.point = 0;
        self.view.error_kind = 0;
        self.view.error_code = 0;
        self.view.cycle = 0;
    }

    /// The face the running (or last) measurement was started from.
    pub fn busy_face(&self) -> Face {
        self.busy_face
    }

    fn decide<P>(
        &mut self,
        req: &Request,
        resolve: impl FnOnce(u16) -> Result<P, Refusal>,
    ) -> (Result<(), Refusal>, Option<Action<P>>) {
        match req.code {
            CODE_START => {
                let check = if self.state == State::Busy {
                    Err(Refusal::Busy)
                } else if self.state == State::Error {
                    Err(Refusal::ErrorPending)
                } else if !self.machine_ok {
                    Err(Refusal::MachineNotReady)
                } else if req.flags & !FLAGS_KNOWN != 0 || req.params.iter().any(|p| !p.is_finite())
                {
                    Err(Refusal::BadRequest)
                } else {
                    resolve(req.program)
                };
                match check {
                    Ok(program) => (
                        Ok(()),
                        Some(Action::Start {
                            seq: req.seq,
                            program,
                            confirm: req.flags & super::register_map::FLAG_CONFIRM != 0,
                        }),
                    ),
                    Err(r) => (Err(r), None),
                }
            }
            CODE_ABORT if self.state == State::Busy => (Ok(()), Some(Action::Abort)),
            CODE_ABORT => (Err(Refusal::NotBusy), None),
            CODE_ACKNOWLEDGE if self.state == State::Busy => (Err(Refusal::Busy), None),
            CODE_ACKNOWLEDGE => {
                self.state = State::Idle;
                self.view.error_kind = 0;
                self.view.error_code = 0;
                (Ok(()), None)
            }
            _ => (Err(Refusal::UnknownCode), None),
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
        self.busy_seq
    }

    /// Is the PLC heartbeat stale while busy (the motion must be aborted)?
    pub fn heartbeat_lost(&self, now: Instant) -> bool {
        match self.heartbeat_timeout {
            Some(t) => {
                self.state == State::Busy
                    && self.busy_face == Face::Plc
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

    fn ready() -> (Handshake, Instant) {
        let now = Instant::now();
        let mut h = Handshake::new(Some(Duration::from_secs(1)), now);
        h.set_machine_ok(true);
        (h, now)
    }

    #[test]
    fn start_runs_once_per_sequence_and_refuses_while_busy() {
        let (mut h, now) = ready();
        let a = h.on_request(&req(CODE_START, 1, 0), now, Ok::<_, Refusal>);
        assert_eq!(
            a,
            Some(Action::Start {
                seq: 1,
                program: 431,
                confirm: false
            })
        );
        assert_eq!(h.view().bits & BIT_BUSY, BIT_BUSY);
        // The same level again: nothing.
        assert_eq!(
            h.on_request(&req(CODE_START, 1, 0), now, Ok::<_, Refusal>),
            None
        );
        // A new start while busy: refused, never queued.
        assert_eq!(
            h.on_request(&req(CODE_START, 2, 0), now, Ok::<_, Refusal>),
            None
        );
        assert_eq!(h.view().ack_seq, 2);
        assert_eq!(h.view().ack_code, CODE_START | REFUSED);
        assert_eq!(h.view().reason, Refusal::Busy as u16);
        assert_eq!(h.finish(Outcome::Done, 431), 1);
        assert_eq!(h.state(), State::Done);
        assert_eq!(h.view().bits & BIT_RESULTS_VALID, BIT_RESULTS_VALID);
    }

    #[test]
    fn error_must_be_acknowledged_before_the_next_start() {
        let (mut h, now) = ready();
        h.on_request(&req(CODE_START, 1, 0), now, Ok::<_, Refusal>);
        h.finish(Outcome::Error { kind: 1, code: 0 }, 0);
        assert_eq!(
            h.on_request(&req(CODE_START, 2, 0), now, Ok::<_, Refusal>),
            None
        );
        assert_eq!(h.view().reason, Refusal::ErrorPending as u16);
        assert_eq!(
            h.on_request(&req(CODE_ACKNOWLEDGE, 3, 0), now, Ok::<_, Refusal>),
            None
        );
        assert_eq!(h.view().ack_code, CODE_ACKNOWLEDGE);
        assert_eq!(h.state(), State::Idle);
        assert_eq!(h.view().error_kind, 0);
        assert!(h
            .on_request(&req(CODE_START, 4, 0), now, Ok::<_, Refusal>)
            .is_some());
    }

    #[test]
    fn refusals_go_into_the_acknowledge_code() {
        let (mut h, now) = ready();
        h.on_request(&req(CODE_START, 1, 0), now, |_| {
            Err::<u16, _>(Refusal::UnknownProgram)
        });
        assert_eq!(h.view().reason, Refusal::UnknownProgram as u16);
        assert_eq!(h.state(), State::Idle);
        h.on_request(&req(CODE_ABORT, 2, 0), now, Ok::<_, Refusal>);
        assert_eq!(h.view().reason, Refusal::NotBusy as u16);
        h.on_request(&req(9, 3, 0), now, Ok::<_, Refusal>);
        assert_eq!(h.view().ack_code, 9 | REFUSED);
        assert_eq!(h.view().reason, Refusal::UnknownCode as u16);
        let mut bad = req(CODE_START, 4, 0);
        bad.params[3] = f32::NAN;
        h.on_request(&bad, now, Ok::<_, Refusal>);
        assert_eq!(h.view().reason, Refusal::BadRequest as u16);
    }

    #[test]
    fn a_command_follows_the_same_rules_and_leaves_the_plc_acknowledge_alone() {
        let (mut h, now) = ready();
        h.on_request(&req(CODE_ACKNOWLEDGE, 7, 0), now, Ok::<_, Refusal>);
        let before = h.view().clone();
        let a = h.command(CODE_START, 431, [0.0; 8], true, now, Ok::<_, Refusal>);
        assert!(matches!(a, Ok(Some(Action::Start { seq: 6, .. }))), "{a:?}");
        assert_eq!(h.state(), State::Busy);
        assert_eq!(h.busy_face(), Face::OpcUa);
        assert_eq!(
            (h.view().ack_seq, h.view().ack_code, h.view().reason),
            (before.ack_seq, before.ack_code, before.reason)
        );
        // The PLC's start while it runs: busy, in the PLC's registers.
        h.on_request(&req(CODE_START, 8, 0), now, Ok::<_, Refusal>);
        assert_eq!(h.view().reason, Refusal::Busy as u16);
        // A second start of the face: busy, to the caller.
        assert_eq!(
            h.command(CODE_START, 431, [0.0; 8], false, now, Ok::<_, Refusal>),
            Err(Refusal::Busy)
        );
        // The PLC's heartbeat does not supervise the face's run.
        assert!(!h.heartbeat_lost(now + Duration::from_secs(5)));
        assert_eq!(
            h.command(CODE_ABORT, 0, [0.0; 8], false, now, Ok::<_, Refusal>),
            Ok(Some(Action::Abort))
        );
        h.finish(Outcome::Aborted(AbortReason::Request), 0);
        assert_eq!(
            h.command(CODE_ABORT, 0, [0.0; 8], false, now, Ok::<_, Refusal>),
            Err(Refusal::NotBusy)
        );
        let mut nan = [0.0; 8];
        nan[2] = f32::INFINITY;
        assert_eq!(
            h.command(CODE_START, 431, nan, false, now, Ok::<_, Refusal>),
            Err(Refusal::BadRequest)
        );
    }

    #[test]
    fn stale_heartbeat_while_busy_is_lost() {
        let (mut h, now) = ready();
        assert!(
            !h.heartbeat_lost(now + Duration::from_secs(5)),
            "idle: no check"
        );
        h.on_request(&req(CODE_START, 1, 0), now, Ok::<_, Refusal>);
        let later = now + Duration::from_millis(900);
        h.on_request(&req(CODE_START, 1, 1), later, Ok::<_, Refusal>);
        assert!(!h.heartbeat_lost(later + Duration::from_millis(900)));
        assert!(h.heartbeat_lost(later + Duration::from_millis(1100)));
        h.finish(Outcome::Aborted(AbortReason::PlcHeartbeat), 0);
        assert_eq!(h.view().error_kind, ERROR_KIND_PLC_HEARTBEAT);
        assert_eq!(h.state(), State::Aborted);
    }
}
