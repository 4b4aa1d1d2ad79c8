//! The PLC face's registers, the face's adapter of the service: the register image, the
//! handshake (the PLC's requests asked of the service, its acknowledge registers and
//! heartbeat) and the connection that owns the writes. The state block, the result
//! blocks and the gateway's heartbeat are drawn from the service before every read and
//! after every write ([`PlcRegisters::sync`]), so what the PLC reads is what every face
//! shows. The Modbus server ([`super::modbus_face`]) does the network.

use super::handshake::{Handshake, PlcRequest};
use super::ownership::{Ownership, Takeover};
use super::register_map::{MapException, RegisterMap};
use super::service::Service;
use std::net::IpAddr;
use std::time::Instant;

/// Why a write was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WriteRefusal {
    /// Another connection owns the writes.
    Busy,
    Map(MapException),
}

pub struct PlcRegisters {
    map: RegisterMap,
    hs: Handshake,
    owner: Ownership,
    /// The service's results last drawn into the result blocks.
    drawn_results: Option<u64>,
}

impl PlcRegisters {
    pub fn new(map: RegisterMap, hs: Handshake, owner: Ownership) -> Self {
        Self {
            map,
            hs,
            owner,
            drawn_results: None,
        }
    }

    /// Draws the service's state into the registers: a start of this face the service
    /// has answered is acknowledged, the state block, the gateway's heartbeat, and the
    /// result blocks when the service's results changed.
    pub fn sync(&mut self, service: &Service, now: Instant) {
        if let Some((id, answer)) = service.last_answer() {
            self.hs.start_answered(id, answer, now);
        }
        self.map.set_state(&self.hs.view(service.status()));
        self.map.set_gateway_heartbeat(service.heartbeat());
        if self.drawn_results != Some(service.results_generation()) {
            let r = service.results();
            self.map.set_results(r.seq, &r.values);
            self.map.set_machine_time(r.seq, r.machine_time.as_ref());
            self.drawn_results = Some(service.results_generation());
        }
    }

    /// A read of the holding registers, as they are now.
    pub fn read(
        &mut self,
        service: &Service,
        addr: u16,
        count: u16,
    ) -> Result<Vec<u16>, MapException> {
        self.sync(service, Instant::now());
        self.map.read(addr, count)
    }

    /// A write of connection `conn` from `ip`: the first connection that writes owns
    /// the request block while it talks (see [`Ownership`]). A refused write changes
    /// nothing, the owner included. A new request is asked of the service.
    pub fn write(
        &mut self,
        service: &mut Service,
        conn: u64,
        ip: IpAddr,
        addr: u16,
        values: &[u16],
    ) -> Result<(), WriteRefusal> {
        let now = Instant::now();
        let mut claim = self.owner.clone();
        let takeover = claim.claim(conn, ip, now).map_err(|_| WriteRefusal::Busy)?;
        self.map.write(addr, values).map_err(WriteRefusal::Map)?;
        self.owner = claim;
        match takeover {
            Some(Takeover::Silent { from, silent }) => tracing::info!(
                connection = conn,
                %ip,
                "PLC face: connection {conn} takes the request block over from connection \
                 {from}, silent for {} ms",
                silent.as_millis()
            ),
            Some(Takeover::SameAddress { from }) => tracing::info!(
                connection = conn,
                %ip,
                "PLC face: connection {conn} takes the request block over from connection \
                 {from} of the same address (the PLC connected again)"
            ),
            None => {}
        }
        if let Some(req) = self.hs.on_request(&self.map.request(), now) {
            self.ask(service, &req);
        }
        self.sync(service, now);
        Ok(())
    }

    /// A new request of the PLC, asked of the service and answered in the acknowledge
    /// registers.
    fn ask(&mut self, service: &mut Service, req: &PlcRequest) {
        let answer = match req.command {
            Ok((command, well_formed)) => service
                .command(command, req.origin(), well_formed, "PLC")
                .map(|pending| pending.map(|p| p.id())),
            Err(r) => {
                tracing::info!(
                    seq = req.seq,
                    code = req.code,
                    reason = r as u16,
                    "request refused by the PLC face ({})",
                    r.describe()
                );
                Err(r)
            }
        };
        self.hs.answered(req, answer);
    }

    /// Connection `conn` sent a request (any): an owner stays the owner.
    pub fn heard(&mut self, conn: u64) {
        self.owner.heard(conn, Instant::now());
    }

    /// The address of the connection that owns the request block, if one does.
    pub fn owner_ip(&self) -> Option<IpAddr> {
        self.owner.owner_ip()
    }

    pub fn disconnected(&mut self, conn: u64) {
        self.owner.disconnected(conn);
    }

    /// Is the PLC's heartbeat stale while a run it started is busy?
    pub fn heartbeat_lost(&mut self, service: &Service, now: Instant) -> bool {
        self.sync(service, now);
        self.hs.heartbeat_lost(service.status(), now)
    }

    /// The register at `addr` as last drawn (tests).
    #[cfg(test)]
    pub fn get(&self, addr: u16) -> u16 {
        self.map.get(addr)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::handshake::{
        BIT_BUSY, BIT_RESULTS_VALID, CODE_ABORT, CODE_ACKNOWLEDGE, CODE_START, REFUSED,
    };
    use crate::serve::measurement::{Command, Origin, State, NO_REQUEST};
    use crate::serve::outcome::{AbortReason, Outcome, Refusal, ERROR_KIND_PLC_HEARTBEAT};
    use crate::serve::register_map::{self as map, WordOrder};
    use crate::serve::results::{Quantity, ResultKey, ResultValues};
    use crate::serve::service::{StartRequest, ToMachine};
    use std::net::Ipv4Addr;
    use std::sync::mpsc::Receiver;
    use std::time::Duration;

    /// The PLC face on a service, and the machine thread's end of the jobs.
    struct Rig {
        service: Service,
        plc: PlcRegisters,
        jobs: Receiver<ToMachine>,
    }

    const PLC: IpAddr = IpAddr::V4(Ipv4Addr::LOCALHOST);

    fn rig() -> Rig {
        let (tx, jobs) = std::sync::mpsc::channel();
        let mut service = Service::new(tx);
        service.set_machine_ok(true);
        let plc = PlcRegisters::new(
            RegisterMap::new(WordOrder::HighFirst, 10_000.0),
            Handshake::new(Some(Duration::from_secs(1)), Instant::now()),
            Ownership::new(Duration::from_secs(10)),
        );
        Rig { service, plc, jobs }
    }

    impl Rig {
        /// The PLC writes its request block.
        fn request(&mut self, code: u16, seq: u16, param: f32, heartbeat: u16) {
            let mut block = vec![code, seq, 431, 0];
            for _ in 0..map::REQ_PARAM_COUNT {
                block.extend(WordOrder::HighFirst.split(param.to_bits()));
            }
            block.push(heartbeat);
            self.plc
                .write(&mut self.service, 1, PLC, map::REQUEST_BASE, &block)
                .unwrap();
        }

        /// The start handed to the machine thread, if one was.
        fn job(&self) -> Option<Box<StartRequest>> {
            match self.jobs.try_recv() {
                Ok(ToMachine::Start(r)) => Some(r),
                _ => None,
            }
        }

        /// The machine thread answers the start it was handed.
        fn prepare(&mut self, answer: Result<(), Refusal>) -> bool {
            let job = self.job().expect("a start for the machine thread");
            self.service.prepared(&job, answer)
        }

        fn reg(&mut self, addr: u16) -> u16 {
            self.plc.read(&self.service, addr, 1).unwrap()[0]
        }

        fn ack(&mut self) -> (u16, u16, u16) {
            (
                self.reg(map::ST_ACK_SEQ),
                self.reg(map::ST_ACK_CODE),
                self.reg(map::ST_REASON),
            )
        }
    }

    #[test]
    fn a_start_runs_once_per_sequence_and_is_acknowledged_once_prepared() {
        let mut r = rig();
        r.request(CODE_START, 1, 0.0, 0);
        // Being prepared: not yet acknowledged, another start is busy.
        assert_eq!(r.ack().0, 0);
        let job = r.job().unwrap();
        assert_eq!(job.start.origin, Origin::Plc { seq: 1 });
        assert!(r
            .service
            .command(Command::Acknowledge, Origin::OpcUa, true, "t")
            .is_err());
        assert!(r.service.prepared(&job, Ok(())));
        assert_eq!(r.ack(), (1, CODE_START, 0));
        assert_eq!(r.reg(map::ST_BITS) & BIT_BUSY, BIT_BUSY);
        // The same level again: nothing; a new start while busy: refused, never queued.
        r.request(CODE_START, 1, 0.0, 0);
        assert!(r.job().is_none());
        r.request(CODE_START, 2, 0.0, 0);
        assert!(r.job().is_none());
        assert_eq!(r.ack(), (2, CODE_START | REFUSED, Refusal::Busy as u16));
        // The results of the run reach the result block with the start's sequence.
        let mut values = ResultValues::new();
        values.insert(ResultKey::Value(Quantity::named("Q158")), 0.25);
        r.service.finish(Outcome::Done, 431, &values, None);
        assert_eq!(r.reg(map::ST_STATE), State::Done as u16);
        assert_eq!(r.reg(map::ST_BITS) & BIT_RESULTS_VALID, BIT_RESULTS_VALID);
        assert_eq!((r.reg(map::RES_SEQ_HEAD), r.reg(map::RES_SEQ_TAIL)), (1, 1));
        // The next start taken: the old results stop matching any request.
        r.request(CODE_START, 3, 0.0, 0);
        assert!(r.prepare(Ok(())));
        assert_eq!(r.reg(map::RES_SEQ_HEAD), NO_REQUEST);
    }

    #[test]
    fn a_start_refused_when_prepared_is_acknowledged_refused_and_a_newer_request_wins() {
        let mut r = rig();
        r.request(CODE_START, 1, 0.0, 0);
        assert!(!r.prepare(Err(Refusal::HistoryUnavailable)));
        assert_eq!(
            r.ack(),
            (1, CODE_START | REFUSED, Refusal::HistoryUnavailable as u16)
        );
        assert_eq!(r.reg(map::ST_STATE), State::Idle as u16);
        // An abort while a start is prepared is taken and keeps its acknowledge.
        r.request(CODE_START, 2, 0.0, 0);
        r.request(CODE_ABORT, 3, 0.0, 0);
        assert!(r.prepare(Ok(())));
        assert_eq!(r.ack(), (3, CODE_ABORT, 0));
        assert_eq!(r.reg(map::ST_STATE), State::Busy as u16);
        assert_eq!(r.service.abort_reason(), Some(AbortReason::Request));
    }

    #[test]
    fn refusals_go_into_the_acknowledge_registers() {
        let mut r = rig();
        r.request(CODE_ABORT, 1, 0.0, 0);
        assert_eq!(r.ack(), (1, CODE_ABORT | REFUSED, Refusal::NotBusy as u16));
        r.request(9, 2, 0.0, 0);
        assert_eq!(r.ack(), (2, 9 | REFUSED, Refusal::UnknownCode as u16));
        r.request(CODE_START, 3, f32::NAN, 0);
        assert_eq!(
            r.ack(),
            (3, CODE_START | REFUSED, Refusal::BadRequest as u16)
        );
        assert!(r.job().is_none());
        // An error must be acknowledged before the next start.
        r.request(CODE_START, 4, 0.0, 0);
        assert!(r.prepare(Ok(())));
        r.service.finish(
            Outcome::Error { kind: 1, code: 0 },
            0,
            &ResultValues::new(),
            None,
        );
        r.request(CODE_START, 5, 0.0, 0);
        assert_eq!(r.reg(map::ST_REASON), Refusal::ErrorPending as u16);
        r.request(CODE_ACKNOWLEDGE, 6, 0.0, 0);
        assert_eq!(r.ack(), (6, CODE_ACKNOWLEDGE, 0));
        assert_eq!(
            (r.reg(map::ST_STATE), r.reg(map::ST_ERROR_KIND)),
            (State::Idle as u16, 0)
        );
    }

    #[test]
    fn an_opc_ua_run_leaves_the_plc_acknowledge_alone_and_is_not_supervised_by_its_heartbeat() {
        let mut r = rig();
        r.request(CODE_ACKNOWLEDGE, 7, 0.0, 0);
        let before = r.ack();
        let start = Command::Start {
            program: 431,
            params: [0.0; map::REQ_PARAM_COUNT],
            confirm: true,
        };
        let pending = r
            .service
            .command(start, Origin::OpcUa, true, "mes")
            .unwrap()
            .expect("a start being prepared");
        assert!(r.prepare(Ok(())));
        assert_eq!(pending.wait(), Ok(()));
        assert_eq!(r.ack(), before);
        // The PLC's start while it runs: busy, in the PLC's registers.
        r.request(CODE_START, 8, 0.0, 0);
        assert_eq!(r.ack(), (8, CODE_START | REFUSED, Refusal::Busy as u16));
        let late = Instant::now() + Duration::from_secs(5);
        assert!(!r.plc.heartbeat_lost(&r.service, late));
        r.service.finish(
            Outcome::Aborted(AbortReason::Request),
            0,
            &ResultValues::new(),
            None,
        );
        assert_eq!(r.reg(map::RES_SEQ_HEAD), NO_REQUEST);
    }

    #[test]
    fn a_stale_heartbeat_while_the_plcs_run_is_busy_is_lost() {
        let mut r = rig();
        r.request(CODE_START, 1, 0.0, 0);
        assert!(r.prepare(Ok(())));
        let now = Instant::now();
        assert!(!r.plc.heartbeat_lost(&r.service, now));
        assert!(r
            .plc
            .heartbeat_lost(&r.service, now + Duration::from_millis(1500)));
        r.service.finish(
            Outcome::Aborted(AbortReason::PlcHeartbeat),
            0,
            &ResultValues::new(),
            None,
        );
        assert_eq!(r.reg(map::ST_ERROR_KIND), ERROR_KIND_PLC_HEARTBEAT);
        assert_eq!(r.reg(map::ST_STATE), State::Aborted as u16);
    }
}
