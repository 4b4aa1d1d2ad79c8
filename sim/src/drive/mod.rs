//! A simulated CiA 402 servo drive on CANopen, built on the same codec as the master
//! (`hal::canopen`, `hal::cia402`): an object dictionary behind an SDO server, NMT with
//! a boot-up at power-on, PDOs as any master maps them (transmission types honoured),
//! a heartbeat producer on the drive's own clock, a heartbeat consumer (0x1016) that
//! stops the drive per 0x6007 when the master falls silent, EMCY, the drive state
//! machine (driven by the controlword however it arrives), cyclic synchronous position with one cycle
//! of servo lag, and touch probe 1 latching the exact position at the instant the probe
//! signal rises. A spindle drive ([`SimDrive::spindle`]) is the same device in profile
//! position mode instead: it moves to a set-point on its own, at its profile velocity.
//!
//! Per SYNC a drive answers in a fixed order: heartbeat (when due), EMCY (when new),
//! event-driven TPDOs whose data changed, then the synchronous TPDOs. The master under
//! lockstep pacing relies on the synchronous TPDO1 being a drive's last frame.
//!
//! Time: the drive's timers (heartbeat, TPDO event timer and inhibit time) run on the
//! clock its host passes in (`now_us`): the wall clock when the drives stand for
//! hardware, the simulated time (SYNCs times the period) on a virtual clock.

mod dictionary;
mod heartbeat;
mod pdo;
mod profile_position;
mod state;
mod touch_probe;

use hal::can::CanFrame;
use hal::canopen::cob_id;
use hal::canopen::emcy::Emcy;
use hal::canopen::nmt::{NmtCommand, NmtState};
use hal::canopen::pdo::{PdoParameters, COB_ID_INVALID};
use hal::canopen::sdo::SdoServer;
use hal::cia402::State;

const PDOS: usize = 4;

/// 0x1000: CiA 402 (profile 0x0192), servo drive (type 0x0002).
pub const DEVICE_TYPE: u32 = 0x0002_0192;
/// 0x1018:1. The simulator has no CiA-assigned vendor-ID: 0 is none.
pub const VENDOR_ID: u32 = 0;
/// 0x1018:2.
pub const PRODUCT_CODE: u32 = 0x0000_0402;
/// 0x1018:3: major revision 1 (upper 16 bits), minor 0.
pub const REVISION: u32 = 0x0001_0000;
/// 0x1018:4 is the node-ID: every simulated drive of a machine has its own serial.
/// 0x6502 of an axis drive: cyclic synchronous position (bit 7) only.
pub const SUPPORTED_DRIVE_MODES: u32 = 1 << 7;
/// 0x6502 of a spindle drive: profile position (bit 0) only.
pub const SPINDLE_DRIVE_MODES: u32 = 1 << 0;
/// 0x1008 of an axis drive.
pub const DEVICE_NAME: &[u8] = b"probebridge simulated CiA 402 drive";
/// 0x1008 of a spindle drive.
pub const SPINDLE_DEVICE_NAME: &[u8] = b"probebridge simulated CiA 402 spindle drive";
/// 0x1006 at power-on and after a reset of communication.
pub const DEFAULT_CYCLE_PERIOD_US: u32 = 2000;
/// 0x1005 at power-on: SYNC on 0x080, consumed (bit 30 clear: this drive never
/// produces SYNC).
pub const DEFAULT_SYNC_COB_ID: u32 = 0x80;
const CYCLIC_SYNCHRONOUS_POSITION: i8 = 8;
const PROFILE_POSITION: i8 = 1;
/// EMCYs held while the drive may not send them (NMT stopped).
const EMCY_QUEUE: usize = 4;

/// 0x6007 (CiA 402 abort connection option code), INTEGER16: what the drive does when
/// the heartbeat it consumes is lost. Negative values are manufacturer-specific: this
/// drive has none.
pub mod abort_connection {
    /// No action (the EMCY still goes out).
    pub const NO_ACTION: i16 = 0;
    /// Fault signal: the drive goes to Fault (fault reaction, then Fault).
    pub const FAULT: i16 = 1;
    /// Disable voltage command: the drive goes to Switch on disabled at once.
    pub const DISABLE_VOLTAGE: i16 = 2;
    /// Quick stop command: the drive stops (Quick stop active), then goes to Switch on
    /// disabled (quick stop option code 2). The default.
    pub const QUICK_STOP: i16 = 3;
}

/// The communication profile area (0x1000-0x1FFF) that a reset of communication
/// restores.
#[derive(Clone, Debug)]
struct Communication {
    cycle_period_us: u32,
    heartbeat_ms: u16,
    /// 0x1016:1: the node whose heartbeat this drive watches (bits 16-23) and the
    /// consumer time in ms (bits 0-15); 0: none watched.
    heartbeat_consumer: u32,
    sync_cob_id: u32,
    emcy_cob_id: u32,
    rpdo: [PdoParameters; PDOS],
    tpdo: [PdoParameters; PDOS],
}

/// The drive profile area (0x6000-0x9FFF) that a reset of the node restores.
#[derive(Clone, Debug)]
struct Application {
    mode: i8,
    controlword: u16,
    target: i32,
    tp_function: u16,
    tp_status: u16,
    tp_pos_edge: i32,
    state: State,
    /// Active fault (its EMCY error code, 0x603F), until a fault reset.
    fault: Option<u16>,
    /// 0x6007, see [`abort_connection`].
    abort_connection: i16,
    /// Profile position: 0x6081 (increments/s), 0x6083 and 0x6084 (increments/s²).
    profile_velocity: u32,
    profile_acceleration: u32,
    profile_deceleration: u32,
    /// Profile position: the set-point being moved to, taken on the rising edge of
    /// controlword bit 4.
    pp_set_point: Option<i32>,
    /// Profile position: statusword bit 12 (set-point acknowledge).
    pp_acknowledged: bool,
    /// Controlword bit 4 as the last step saw it (the edge is judged once per SYNC,
    /// after the whole RPDO took effect: target and controlword together).
    pp_bit4_seen: bool,
}

/// The drive's objects. Plain fields, `Copy` data only: SYNC processing allocates
/// nothing.
#[derive(Clone, Debug)]
struct Objects {
    node: u8,
    /// 0x6502: the modes of operation this drive has.
    supported_modes: u32,
    /// 0x1008.
    device_name: &'static [u8],
    comm: Communication,
    app: Application,
    /// Encoder position: physical, no reset changes it.
    actual: i32,
    /// An RPDO of the wrong length came in; cleared by the next good one.
    pdo_length_error: bool,
    /// The watched heartbeat (0x1016) is lost; cleared when it comes back.
    heartbeat_lost: bool,
    /// 0x1016 was written: the consumer waits for a first heartbeat again.
    consumer_restart: bool,
    /// A quick stop for a lost connection ends in Switch on disabled at this time (on
    /// the drive's clock); until then the controlword cannot re-enable the drive.
    quick_stop_until_us: Option<u64>,
    /// EMCYs to send, oldest first.
    emcy: [Emcy; EMCY_QUEUE],
    emcy_len: usize,
    /// 0x1017 was written: the producer starts over.
    heartbeat_restart: bool,
}

/// A lost heartbeat, as the drive that consumed it recorded it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HeartbeatLoss {
    /// The node that fell silent (0x1016:1 bits 16-23).
    pub node: u8,
    /// The consumer time, ms (0x1016:1 bits 0-15).
    pub consumer_ms: u16,
    /// Time since its last heartbeat when the loss was noticed, µs.
    pub silent_us: u64,
    /// When the loss was noticed, on the drive's clock, µs.
    pub at_us: u64,
    /// The state the drive was in, and the one its 0x6007 reaction left it in.
    pub from: State,
    pub to: State,
}

/// The heartbeat consumer of 0x1016:1. Its clock follows the drive's, but advances by
/// at most half the consumer time and at most [`CONSUMER_LOOK_MAX_US`] between two
/// looks: a drive whose host stalled (a loaded machine, an emulated CPU) did not
/// watch, and cannot judge what it missed (a real drive does not stall). Frames queued
/// meanwhile, the heartbeat among them, are taken before it judges again.
#[derive(Clone, Copy, Debug, Default)]
struct Consumer {
    clock_us: u64,
    /// The drive's clock at the last look.
    looked_at_us: Option<u64>,
    /// Consumer clock at the last heartbeat; `None`: none since the (re)start, so
    /// nothing is watched yet (CiA 301: monitoring starts with the first heartbeat).
    seen_us: Option<u64>,
    /// The loss is reported, until the heartbeat comes back.
    lost: bool,
}

/// One simulated drive.
#[derive(Clone, Debug)]
pub struct SimDrive {
    od: Objects,
    sdo: SdoServer,
    nmt: NmtState,
    /// Encoder position at the start of the current step (increments).
    step_from: i32,
    /// Synchronous RPDO data received since the last SYNC: it takes effect at the next.
    rpdo_at_sync: [Option<([u8; 8], usize)>; PDOS],
    /// SYNCs since a TPDO of transmission type 1..=240 was last sent.
    tpdo_syncs: [u8; PDOS],
    /// Last data sent per TPDO (change detection for acyclic and event-driven ones).
    last_sent: [Option<([u8; 8], usize)>; PDOS],
    /// When each TPDO was last sent, on the drive's clock (inhibit time, event timer).
    sent_at_us: [u64; PDOS],
    /// The drive's clock, µs, as last told by [`Self::poll`] or [`Self::answer_sync`].
    now_us: u64,
    /// Heartbeat producer: when the last heartbeat was due; `None`: not started.
    heartbeat_at_us: Option<u64>,
    /// Heartbeat consumer (0x1016).
    consumer: Consumer,
    /// The last loss of the watched heartbeat, and whether it was taken
    /// ([`SimDrive::take_heartbeat_loss`]).
    heartbeat_loss: Option<(HeartbeatLoss, bool)>,
    /// Event-driven TPDOs may be due: a frame was taken or a step made since the last
    /// look, or one waits out its inhibit time. (Packing them after every frame on a
    /// busy bus would cost the host for nothing.)
    events_pending: bool,
    /// Stops answering anything (a node that fell off the bus).
    pub silent: bool,
}

impl SimDrive {
    /// A drive at encoder position `position_inc`, just powered on (pre-operational;
    /// [`Self::power_on`] sends its boot-up).
    pub fn new(node: u8, position_inc: i32) -> Self {
        Self {
            od: Objects::new(node, position_inc),
            sdo: SdoServer::new(node),
            nmt: NmtState::PreOperational,
            step_from: position_inc,
            rpdo_at_sync: [None; PDOS],
            tpdo_syncs: [0; PDOS],
            last_sent: [None; PDOS],
            sent_at_us: [0; PDOS],
            now_us: 0,
            heartbeat_at_us: None,
            consumer: Consumer::default(),
            heartbeat_loss: None,
            events_pending: true,
            silent: false,
        }
    }

    pub fn node(&self) -> u8 {
        self.od.node
    }

    pub fn state(&self) -> State {
        self.od.app.state
    }

    /// 0x6041 as it is now.
    pub fn statusword(&self) -> u16 {
        self.od.statusword()
    }

    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }

    /// A spindle drive at encoder position `position_inc`: profile position only
    /// (0x6502 bit 0), for oriented spindle stops.
    pub fn spindle(node: u8, position_inc: i32) -> Self {
        let mut d = Self::new(node, position_inc);
        d.od.supported_modes = SPINDLE_DRIVE_MODES;
        d.od.device_name = SPINDLE_DEVICE_NAME;
        d
    }

    /// Encoder position, increments.
    pub fn actual_inc(&self) -> i32 {
        self.od.actual
    }

    /// Where the drive will be at the end of the next step: the CSP target when it is
    /// enabled (one cycle of servo lag), in profile position one cycle's travel towards
    /// the set-point, else where it is.
    pub fn next_position_inc(&self) -> i32 {
        let a = &self.od.app;
        if a.state != State::OperationEnabled || a.fault.is_some() {
            return self.od.actual;
        }
        match a.mode {
            CYCLIC_SYNCHRONOUS_POSITION => a.target,
            PROFILE_POSITION => self.profile_position_next(),
            _ => self.od.actual,
        }
    }

    pub fn cycle_period_us(&self) -> u32 {
        self.od.comm.cycle_period_us
    }

    /// Whether this drive takes frames with `cob_id` as SYNC (0x1005).
    pub fn consumes_sync(&self, cob_id: u16) -> bool {
        self.od.comm.sync_cob_id & 0x7FF == u32::from(cob_id)
    }

    /// Power-on: the boot-up message (CiA 301: the node enters pre-operational).
    pub fn power_on(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        if !self.silent {
            tx(&hal::canopen::heartbeat::boot_up(self.od.node));
        }
    }

    /// Handles an NMT, SDO or RPDO frame addressed to this drive; answers through `tx`.
    pub fn on_frame(&mut self, f: &CanFrame, tx: &mut dyn FnMut(&CanFrame)) {
        if self.silent {
            return;
        }
        match cob_id::classify(f.cob_id()) {
            cob_id::CobKind::Nmt => {
                if let Ok((cmd, node)) = hal::canopen::nmt::decode(f) {
                    if node == 0 || node == self.od.node {
                        self.on_nmt(cmd, tx);
                        self.events_pending = true;
                    }
                }
            }
            cob_id::CobKind::SdoRequest { node }
                if node == self.od.node && self.nmt != NmtState::Stopped =>
            {
                if let Some(r) = self.sdo.on_frame(f, &mut self.od) {
                    tx(&r);
                }
                self.events_pending = true;
            }
            cob_id::CobKind::Heartbeat { node } if !f.is_rtr() && f.data().len() == 1 => {
                self.on_heartbeat(node);
            }
            _ if self.nmt == NmtState::Operational && !f.is_rtr() => {
                let rx = &self.od.comm.rpdo;
                if let Some(i) = rx
                    .iter()
                    .position(|p| p.is_enabled() && p.cob_id() == f.cob_id())
                {
                    self.on_rpdo(i, f.data());
                    self.events_pending = true;
                }
            }
            _ => {}
        }
        self.send_emcy(tx);
    }

    /// The node restarts on its own (a watchdog reset, a power dip): as an NMT reset
    /// node, it sends its boot-up and is pre-operational with its defaults.
    pub fn reboot(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        self.on_nmt(NmtCommand::ResetNode, tx);
    }

    fn on_nmt(&mut self, cmd: NmtCommand, tx: &mut dyn FnMut(&CanFrame)) {
        match cmd {
            NmtCommand::Start => self.nmt = NmtState::Operational,
            NmtCommand::Stop => self.nmt = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.nmt = NmtState::PreOperational,
            NmtCommand::ResetNode => {
                // The application starts over too; the axis stays where it is.
                self.od.app = Application::new(self.od.actual);
                self.od.quick_stop_until_us = None;
                self.od.emcy_len = 0;
                self.reset_communication(tx);
            }
            NmtCommand::ResetCommunication => self.reset_communication(tx),
        }
    }

    /// CiA 301: the communication area (0x1000-0x1FFF) back to its power-on values,
    /// then boot-up into pre-operational. The drive profile area is untouched.
    fn reset_communication(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        let node = self.od.node;
        self.od.comm = Communication::new(node);
        if self.od.pdo_length_error {
            // A communication error: gone with the communication that had it.
            self.od.pdo_length_error = false;
            self.od.emcy_len = 0;
        }
        self.od.heartbeat_restart = true;
        // 0x1016 is back to 0: nothing is watched, and a loss is gone with it.
        self.od.consumer_restart = true;
        self.od.heartbeat_lost = false;
        self.sdo = SdoServer::new(node);
        self.rpdo_at_sync = [None; PDOS];
        self.tpdo_syncs = [0; PDOS];
        self.last_sent = [None; PDOS];
        self.nmt = NmtState::PreOperational;
        tx(&hal::canopen::heartbeat::boot_up(node));
    }

    /// Sends the queued EMCYs on the COB-ID of 0x1014, except in NMT stopped (CiA
    /// 301: no EMCY there; they wait until the node leaves it).
    fn send_emcy(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        if self.nmt == NmtState::Stopped || self.od.emcy_len == 0 {
            return;
        }
        let cob = self.od.comm.emcy_cob_id;
        for e in &self.od.emcy[..self.od.emcy_len] {
            if cob & COB_ID_INVALID != 0 {
                break;
            }
            let f = e.encode(self.od.node);
            if let Some(f) = CanFrame::new((cob & 0x7FF) as u16, f.data()) {
                tx(&f);
            }
        }
        self.od.emcy_len = 0;
    }

    /// Time passes on the drive's clock (`now_us`, µs, never going back): the
    /// heartbeat when due (0x1017 ms after the last), queued EMCYs, and in operational
    /// the event-driven TPDOs whose data changed or whose event timer expired.
    pub fn poll(&mut self, now_us: u64, tx: &mut dyn FnMut(&CanFrame)) {
        if self.silent {
            return;
        }
        self.now_us = now_us;
        self.produce_heartbeat(tx);
        self.consume_heartbeat();
        self.end_quick_stop();
        self.send_emcy(tx);
        let timers = self
            .od
            .comm
            .tpdo
            .iter()
            .any(|p| p.is_enabled() && p.transmission_type() >= 254 && p.event_timer_ms() > 0);
        if self.nmt == NmtState::Operational && (self.events_pending || timers) {
            self.events_pending = self.send_tpdos(false, tx);
        }
    }

    /// When [`Self::poll`] next has something to do on its own (heartbeat, an event
    /// timer), on the drive's clock; `None`: nothing timed.
    pub fn next_deadline_us(&self) -> Option<u64> {
        if self.silent {
            return None;
        }
        let period_us = u64::from(self.od.comm.heartbeat_ms) * 1000;
        let heartbeat = if self.od.heartbeat_restart {
            Some(self.now_us)
        } else {
            self.heartbeat_at_us
                .filter(|_| period_us > 0)
                .map(|t| t + period_us)
        };
        let (_, ms) = self.watched();
        let c = &self.consumer;
        // When the watched heartbeat expires, on the drive's clock.
        let expiry = c
            .seen_us
            .filter(|_| ms > 0 && !c.lost && !self.od.consumer_restart)
            .map(|seen| self.now_us + (seen + u64::from(ms) * 1000 + 1).saturating_sub(c.clock_us));
        let quick_stop = self.od.quick_stop_until_us;
        let operational = self.nmt == NmtState::Operational;
        let timers = self.od.comm.tpdo.iter().enumerate().filter_map(|(i, p)| {
            let event = p.transmission_type() >= 254 && p.event_timer_ms() > 0;
            (operational && p.is_enabled() && event)
                .then(|| self.sent_at_us[i] + u64::from(p.event_timer_ms()) * 1000)
        });
        // A change held back by the inhibit time goes out when it is over.
        let inhibited = self.od.comm.tpdo.iter().enumerate().filter_map(|(i, p)| {
            let event = p.transmission_type() >= 254 && p.inhibit_time_100us() > 0;
            (operational && self.events_pending && p.is_enabled() && event)
                .then(|| self.sent_at_us[i] + u64::from(p.inhibit_time_100us()) * 100)
        });
        heartbeat
            .into_iter()
            .chain(expiry)
            .chain(quick_stop)
            .chain(timers)
            .chain(inhibited)
            .min()
    }

    /// Answers one SYNC (after [`Self::end_step`]), at `now_us` on the drive's clock:
    /// heartbeat when due, EMCY, event TPDOs that changed, then synchronous TPDOs
    /// (type 0 when its data changed, type n on every n-th SYNC).
    pub fn answer_sync(&mut self, now_us: u64, tx: &mut dyn FnMut(&CanFrame)) {
        if self.silent {
            return;
        }
        // The step may have changed mapped values.
        self.events_pending = true;
        self.poll(now_us, tx);
        if self.nmt != NmtState::Operational {
            return;
        }
        self.send_tpdos(true, tx);
    }
}
