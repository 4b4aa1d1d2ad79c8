//! The level-based handshake with the PLC, without I/O: a change of the request
//! sequence asks the service once (the PLC face's command, by the rules every face
//! follows: [`super::measurement`]); the gateway answers by echoing the sequence and
//! the code (bit 15 set: refused, with a reason). Here: the request block read as a
//! command, the acknowledge registers, the PLC's heartbeat, and the state block drawn
//! from the service's [`Status`].

use super::measurement::{Command, Origin, StartId, State, Status, NO_REQUEST};
use super::register_map::{Request, StateView, FLAGS_KNOWN, FLAG_CONFIRM};
use std::time::{Duration, Instant};

pub use super::outcome::Refusal;

pub const CODE_START: u16 = 1;
pub const CODE_ABORT: u16 = 2;
pub const CODE_ACKNOWLEDGE: u16 = 3;
pub const REFUSED: u16 = 0x8000;

/// Bits of the bits register.
pub const BIT_READY: u16 = 1 << 0;
pub const BIT_BUSY: u16 = 1 << 1;
pub const BIT_DONE: u16 = 1 << 2;
pub const BIT_ERROR: u16 = 1 << 3;
pub const BIT_MACHINE_OK: u16 = 1 << 4;
pub const BIT_RESULTS_VALID: u16 = 1 << 5;
/// Ends of runs are in the spool, not yet in the history.
pub const BIT_NOT_RECORDED: u16 = 1 << 6;

/// A new request of the PLC: the command it asks the service for, or why it is none.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlcRequest {
    pub seq: u16,
    pub code: u16,
    /// The command, and whether its flags have no unknown bits.
    pub command: Result<(Command, bool), Refusal>,
}

impl PlcRequest {
    pub fn origin(&self) -> Origin {
        Origin::Plc { seq: self.seq }
    }
}

/// The acknowledge registers (32..34).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Acknowledge {
    seq: u16,
    code: u16,
    reason: u16,
}

#[derive(Debug)]
pub struct Handshake {
    last_seq: u16,
    ack: Acknowledge,
    /// The PLC's start being prepared by the service: acknowledged once answered,
    /// unless the PLC has sent a newer request since.
    awaiting: Option<(StartId, u16)>,
    /// The last answer of the service seen (a run it began restarts the heartbeat
    /// supervision).
    seen_answer: Option<StartId>,
    plc_heartbeat: u16,
    heartbeat_seen: Instant,
    heartbeat_timeout: Option<Duration>,
}

impl Handshake {
    pub fn new(heartbeat_timeout: Option<Duration>, now: Instant) -> Self {
        Self {
            last_seq: NO_REQUEST,
            ack: Acknowledge::default(),
            awaiting: None,
            seen_answer: None,
            plc_heartbeat: 0,
            heartbeat_seen: now,
            heartbeat_timeout,
        }
    }

    /// Looks at the request block: a new sequence is a request, to be asked of the
    /// service and answered with [`Handshake::answered`]. A request with sequence 0
    /// ([`NO_REQUEST`]) is never taken.
    pub fn on_request(&mut self, req: &Request, now: Instant) -> Option<PlcRequest> {
        if req.plc_heartbeat != self.plc_heartbeat {
            self.plc_heartbeat = req.plc_heartbeat;
            self.heartbeat_seen = now;
        }
        if req.seq == NO_REQUEST || req.seq == self.last_seq {
            return None;
        }
        self.last_seq = req.seq;
        self.awaiting = None;
        let command = match req.code {
            CODE_START => Ok((
                Command::Start {
                    program: req.program,
                    params: req.params,
                    confirm: req.flags & FLAG_CONFIRM != 0,
                },
                req.flags & !FLAGS_KNOWN == 0,
            )),
            CODE_ABORT => Ok((Command::Abort, true)),
            CODE_ACKNOWLEDGE => Ok((Command::Acknowledge, true)),
            _ => Err(Refusal::UnknownCode),
        };
        Some(PlcRequest {
            seq: req.seq,
            code: req.code,
            command,
        })
    }

    /// The service's answer to a request: taken or refused at once, or a start being
    /// prepared (`Ok(Some(id))`), acknowledged once the service answers it
    /// ([`Handshake::start_answered`]): the PLC waits for register 32.
    pub fn answered(&mut self, req: &PlcRequest, answer: Result<Option<StartId>, Refusal>) {
        match answer {
            Ok(Some(id)) => self.awaiting = Some((id, req.seq)),
            Ok(None) => self.acknowledge(req.seq, req.code, Ok(())),
            Err(r) => self.acknowledge(req.seq, req.code, Err(r)),
        }
    }

    /// The service answered start `id` (whoever asked): the PLC's start is
    /// acknowledged if it is the one awaited and the PLC sent nothing newer; a run
    /// taken restarts the heartbeat supervision.
    pub fn start_answered(&mut self, id: StartId, answer: Result<(), Refusal>, now: Instant) {
        if self.seen_answer == Some(id) {
            return;
        }
        self.seen_answer = Some(id);
        if answer.is_ok() {
            self.heartbeat_seen = now;
        }
        if let Some((awaited, seq)) = self.awaiting {
            if awaited == id {
                self.awaiting = None;
                if seq == self.last_seq {
                    self.acknowledge(seq, CODE_START, answer);
                }
            }
        }
    }

    fn acknowledge(&mut self, seq: u16, code: u16, answer: Result<(), Refusal>) {
        self.ack = match answer {
            Ok(()) => Acknowledge {
                seq,
                code,
                reason: 0,
            },
            Err(r) => Acknowledge {
                seq,
                code: code | REFUSED,
                reason: r as u16,
            },
        };
    }

    /// The state block: the service's status and this face's acknowledge.
    pub fn view(&self, s: &Status) -> StateView {
        let mut bits = 0;
        if s.ready() {
            bits |= BIT_READY;
        }
        match s.state {
            State::Busy => bits |= BIT_BUSY,
            State::Done => bits |= BIT_DONE | BIT_RESULTS_VALID,
            State::Error => bits |= BIT_ERROR,
            State::Idle | State::Aborted => {}
        }
        if s.machine_ok {
            bits |= BIT_MACHINE_OK;
        }
        if s.not_recorded {
            bits |= BIT_NOT_RECORDED;
        }
        StateView {
            ack_seq: self.ack.seq,
            ack_code: self.ack.code,
            reason: self.ack.reason,
            state: s.state as u16,
            bits,
            progress_permille: s.progress_permille,
            error_kind: s.error_kind,
            error_code: s.error_code,
            point: s.point,
            program: s.program,
            cycle: s.cycle,
        }
    }

    /// Is the PLC heartbeat stale while a run the PLC started is busy (the motion must
    /// be aborted)?
    pub fn heartbeat_lost(&self, s: &Status, now: Instant) -> bool {
        match self.heartbeat_timeout {
            Some(t) => {
                s.state == State::Busy
                    && matches!(s.origin, Some(Origin::Plc { .. }))
                    && now.duration_since(self.heartbeat_seen) > t
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::measurement::START_PARAMS;

    fn req(code: u16, seq: u16, hb: u16) -> Request {
        Request {
            code,
            seq,
            program: 431,
            flags: 0,
            params: [0.0; START_PARAMS],
            plc_heartbeat: hb,
        }
    }

    #[test]
    fn a_new_sequence_is_one_request_and_sequence_0_none() {
        let now = Instant::now();
        let mut h = Handshake::new(None, now);
        let mut r = req(CODE_START, 1, 0);
        r.flags = FLAG_CONFIRM;
        let asked = h.on_request(&r, now).expect("a new sequence");
        assert_eq!(asked.origin(), Origin::Plc { seq: 1 });
        let Ok((Command::Start { confirm, .. }, true)) = asked.command else {
            panic!("{asked:?}")
        };
        assert!(confirm);
        // The same level again, and sequence 0 (no request): nothing.
        assert_eq!(h.on_request(&r, now), None);
        assert_eq!(h.on_request(&req(CODE_START, NO_REQUEST, 0), now), None);
        r.seq = 2;
        r.flags = 0x40;
        assert!(matches!(
            h.on_request(&r, now).map(|a| a.command),
            Some(Ok((Command::Start { .. }, false)))
        ));
        let unknown = h.on_request(&req(9, 3, 0), now).expect("a new sequence");
        assert_eq!(unknown.command, Err(Refusal::UnknownCode));
        h.answered(&unknown, Err(Refusal::UnknownCode));
        let v = h.view(&Status::default());
        assert_eq!((v.ack_seq, v.ack_code, v.reason), (3, 9 | REFUSED, 2));
    }

    #[test]
    fn a_start_is_acknowledged_once_answered_unless_a_newer_request_came() {
        let now = Instant::now();
        let mut h = Handshake::new(None, now);
        let start = h.on_request(&req(CODE_START, 5, 0), now).unwrap();
        h.answered(&start, Ok(Some(1)));
        assert_eq!(
            h.view(&Status::default()).ack_seq,
            0,
            "not before the answer"
        );
        // Another start's answer is not this one's.
        h.start_answered(7, Err(Refusal::Busy), now);
        assert_eq!(h.view(&Status::default()).ack_seq, 0);
        h.start_answered(1, Err(Refusal::UnknownProgram), now);
        let v = h.view(&Status::default());
        assert_eq!(
            (v.ack_seq, v.ack_code, v.reason),
            (5, CODE_START | REFUSED, Refusal::UnknownProgram as u16)
        );
        // A newer request keeps its own acknowledge when the start is answered after.
        let start = h.on_request(&req(CODE_START, 6, 0), now).unwrap();
        h.answered(&start, Ok(Some(2)));
        let abort = h.on_request(&req(CODE_ABORT, 7, 0), now).unwrap();
        h.answered(&abort, Ok(None));
        h.start_answered(2, Ok(()), now);
        let v = h.view(&Status::default());
        assert_eq!((v.ack_seq, v.ack_code, v.reason), (7, CODE_ABORT, 0));
    }

    #[test]
    fn the_bits_follow_the_status() {
        let h = Handshake::new(None, Instant::now());
        let mut s = Status {
            machine_ok: true,
            ..Status::default()
        };
        assert_eq!(h.view(&s).bits, BIT_READY | BIT_MACHINE_OK);
        s.state = State::Busy;
        s.not_recorded = true;
        assert_eq!(
            h.view(&s).bits,
            BIT_BUSY | BIT_MACHINE_OK | BIT_NOT_RECORDED
        );
        s.state = State::Done;
        s.not_recorded = false;
        assert_eq!(
            h.view(&s).bits,
            BIT_READY | BIT_DONE | BIT_RESULTS_VALID | BIT_MACHINE_OK
        );
        s.state = State::Error;
        s.machine_ok = false;
        assert_eq!(h.view(&s).bits, BIT_ERROR);
    }

    #[test]
    fn a_stale_heartbeat_counts_only_while_a_plc_run_is_busy() {
        let now = Instant::now();
        let mut h = Handshake::new(Some(Duration::from_secs(1)), now);
        let mut s = Status {
            machine_ok: true,
            ..Status::default()
        };
        let late = now + Duration::from_secs(5);
        assert!(!h.heartbeat_lost(&s, late), "idle: no check");
        s.state = State::Busy;
        s.origin = Some(Origin::OpcUa);
        assert!(!h.heartbeat_lost(&s, late), "not the PLC's run");
        s.origin = Some(Origin::Plc { seq: 1 });
        assert!(h.heartbeat_lost(&s, late));
        // A run taken restarts the supervision; the PLC's heartbeat keeps it alive.
        let t = now + Duration::from_millis(900);
        h.start_answered(1, Ok(()), t);
        h.on_request(&req(CODE_START, 1, 1), t + Duration::from_millis(900));
        assert!(!h.heartbeat_lost(&s, t + Duration::from_millis(1800)));
        assert!(h.heartbeat_lost(&s, t + Duration::from_millis(2000)));
    }
}
