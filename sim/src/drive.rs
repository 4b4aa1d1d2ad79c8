//! A simulated CiA 402 servo drive on CANopen, built on the same codec as the master
//! (`hal::canopen`, `hal::cia402`): an object dictionary behind an SDO server, NMT with
//! a boot-up at power-on, PDOs as any master maps them (transmission types honoured),
//! a heartbeat producer on the drive's own clock, a heartbeat consumer (0x1016) that
//! stops the drive per 0x6007 when the master falls silent, EMCY, the drive state
//! machine (driven by the controlword however it arrives), cyclic synchronous position with one cycle
//! of servo lag, and touch probe 1 latching the exact position at the instant the probe
//! signal rises.
//!
//! Per SYNC a drive answers in a fixed order: heartbeat (when due), EMCY (when new),
//! event-driven TPDOs whose data changed, then the synchronous TPDOs. The master under
//! lockstep pacing relies on the synchronous TPDO1 being a drive's last frame.
//!
//! Time: the drive's timers (heartbeat, TPDO event timer and inhibit time) run on the
//! clock its host passes in (`now_us`): the wall clock when the drives stand for
//! hardware, the simulated time (SYNCs times the period) on a virtual clock.

use hal::can::CanFrame;
use hal::canopen::cob_id;
use hal::canopen::emcy::{code as emcy_code, error_register, Emcy};
use hal::canopen::heartbeat;
use hal::canopen::nmt::{NmtCommand, NmtState};
use hal::canopen::object as obj;
use hal::canopen::pdo::{
    communication_index, default_cob_id_entry, MapEntry, PdoDirection, PdoParameters,
    COB_ID_EXTENDED, COB_ID_INVALID,
};
use hal::canopen::sdo::{ObjectDictionary, SdoAbortCode, SdoServer};
use hal::cia402::controlword::{fault_reset_edge, Command};
use hal::cia402::{Probe, State, Statusword, TouchProbeFunction, TouchProbeStatus};

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
/// 0x6502: cyclic synchronous position (bit 7) only.
pub const SUPPORTED_DRIVE_MODES: u32 = 1 << 7;
/// 0x1006 at power-on and after a reset of communication.
pub const DEFAULT_CYCLE_PERIOD_US: u32 = 2000;
/// 0x1005 at power-on: SYNC on 0x080, consumed (bit 30 clear: this drive never
/// produces SYNC).
pub const DEFAULT_SYNC_COB_ID: u32 = 0x80;
const CYCLIC_SYNCHRONOUS_POSITION: i8 = 8;
/// EMCYs held while the drive may not send them (NMT stopped).
const EMCY_QUEUE: usize = 4;

const DEVICE_NAME: &[u8] = b"probebridge simulated CiA 402 drive";

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

/// A PDO of the predefined connection set, invalid until a master configures it (an
/// empty PDO has nothing to carry).
fn pdo_at_power_on(direction: PdoDirection, num: u8, node: u8) -> PdoParameters {
    let mut p = PdoParameters::new(direction, num, node).expect("PDO numbers 1..=4");
    let cob = default_cob_id_entry(direction, num, node).expect("PDO numbers 1..=4");
    let index = communication_index(direction, num).expect("PDO numbers 1..=4");
    p.write(index, 1, &(cob | COB_ID_INVALID).to_le_bytes(), |_| true)
        .expect("a valid COB-ID entry");
    p
}

impl Communication {
    fn new(node: u8) -> Self {
        Self {
            cycle_period_us: DEFAULT_CYCLE_PERIOD_US,
            heartbeat_ms: 0,
            heartbeat_consumer: 0,
            sync_cob_id: DEFAULT_SYNC_COB_ID,
            emcy_cob_id: u32::from(cob_id::emcy_cob(node)),
            rpdo: core::array::from_fn(|i| pdo_at_power_on(PdoDirection::Rpdo, i as u8 + 1, node)),
            tpdo: core::array::from_fn(|i| pdo_at_power_on(PdoDirection::Tpdo, i as u8 + 1, node)),
        }
    }
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
}

impl Application {
    fn new(position_inc: i32) -> Self {
        Self {
            mode: 0,
            controlword: 0,
            target: position_inc,
            tp_function: 0,
            tp_status: 0,
            tp_pos_edge: 0,
            state: State::SwitchOnDisabled,
            fault: None,
            abort_connection: abort_connection::QUICK_STOP,
        }
    }
}

/// The drive's objects. Plain fields, `Copy` data only: SYNC processing allocates
/// nothing.
#[derive(Clone, Debug)]
struct Objects {
    node: u8,
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

impl Objects {
    fn new(node: u8, position_inc: i32) -> Self {
        Self {
            node,
            comm: Communication::new(node),
            app: Application::new(position_inc),
            actual: position_inc,
            pdo_length_error: false,
            heartbeat_lost: false,
            consumer_restart: true,
            quick_stop_until_us: None,
            emcy: [Emcy {
                error_code: 0,
                error_register: 0,
                manufacturer: [0; 5],
            }; EMCY_QUEUE],
            emcy_len: 0,
            heartbeat_restart: true,
        }
    }

    /// 0x1001: generic bit with any error, plus the class of each active one.
    fn error_register(&self) -> u8 {
        let mut r = 0;
        if let Some(code) = self.app.fault {
            r |= error_register::GENERIC
                | match code >> 8 {
                    0x20..=0x2F => error_register::CURRENT,
                    0x30..=0x3F => error_register::VOLTAGE,
                    0x40..=0x4F => error_register::TEMPERATURE,
                    0x81 | 0x82 => error_register::COMMUNICATION,
                    0xFF => error_register::MANUFACTURER,
                    _ => 0,
                };
        }
        if self.pdo_length_error || self.heartbeat_lost {
            r |= error_register::GENERIC | error_register::COMMUNICATION;
        }
        r
    }

    /// Queues an EMCY whose error register byte is 0x1001 as it is now (code 0x0000:
    /// an error went away). A full queue drops the oldest.
    fn push_emcy(&mut self, code: u16) {
        if self.emcy_len == EMCY_QUEUE {
            self.emcy.copy_within(1.., 0);
            self.emcy_len -= 1;
        }
        self.emcy[self.emcy_len] = Emcy {
            error_code: code,
            error_register: self.error_register(),
            manufacturer: [0; 5],
        };
        self.emcy_len += 1;
    }

    /// 0x6041: the state bits, remote (the controlword is obeyed), voltage enabled
    /// while the power stage is switched on, and in cyclic synchronous position with
    /// operation enabled bit 12: the drive follows the target position.
    fn statusword(&self) -> u16 {
        let s = self.app.state;
        Statusword(s.statusword_bits() | Statusword::REMOTE)
            .with(
                Statusword::VOLTAGE_ENABLED,
                matches!(
                    s,
                    State::ReadyToSwitchOn
                        | State::SwitchedOn
                        | State::OperationEnabled
                        | State::QuickStopActive
                ),
            )
            .with(
                Statusword::TARGET_POSITION_FOLLOWED,
                s == State::OperationEnabled && self.app.mode == CYCLIC_SYNCHRONOUS_POSITION,
            )
            .bits()
    }

    /// Value of a mappable object as raw bits.
    fn mapped_value(&self, index: u16, sub: u8) -> Option<u64> {
        Some(match (index, sub) {
            (obj::CONTROLWORD, 0) => self.app.controlword as u64,
            (obj::STATUSWORD, 0) => self.statusword() as u64,
            (obj::MODES_OF_OPERATION, 0) | (obj::MODES_OF_OPERATION_DISPLAY, 0) => {
                self.app.mode as u8 as u64
            }
            (obj::POSITION_ACTUAL_VALUE, 0) => self.actual as u32 as u64,
            (obj::TARGET_POSITION, 0) => self.app.target as u32 as u64,
            (obj::ERROR_CODE, 0) => self.app.fault.unwrap_or(0) as u64,
            (obj::TOUCH_PROBE_FUNCTION, 0) => self.app.tp_function as u64,
            (obj::TOUCH_PROBE_STATUS, 0) => self.app.tp_status as u64,
            (obj::TOUCH_PROBE_1_POSITIVE_EDGE, 0) => self.app.tp_pos_edge as u32 as u64,
            _ => return None,
        })
    }

    /// Writes an object the master may write through an RPDO or SDO, with its effect:
    /// a controlword steps the state machine, a touch probe function (re)arms.
    fn write_mapped(&mut self, index: u16, sub: u8, v: u64) -> Result<(), SdoAbortCode> {
        match (index, sub) {
            (obj::CONTROLWORD, 0) => self.apply_controlword(v as u16),
            (obj::TARGET_POSITION, 0) => self.app.target = v as u32 as i32,
            (obj::MODES_OF_OPERATION, 0) => self.app.mode = v as u8 as i8,
            (obj::TOUCH_PROBE_FUNCTION, 0) => {
                self.app.tp_function = v as u16;
                self.apply_touch_probe_function();
            }
            _ => return Err(SdoAbortCode::CANNOT_BE_MAPPED),
        }
        Ok(())
    }

    /// The state machine takes `cw`. A fault reset (bit 7 rising) in Fault clears the
    /// fault (its cause is gone in the simulation; a collision that persists comes
    /// back at the next step) and sends the EMCY "error reset".
    fn apply_controlword(&mut self, cw: u16) {
        let prev = self.app.controlword;
        if self.quick_stop_until_us.is_some() {
            // Quick stop option code 2: no way back to Operation enabled (CiA 402
            // transition 16 needs 5..8); Disable voltage ends the stop early.
            if Command::decode(cw) == Some(Command::DisableVoltage) {
                self.app.state = State::SwitchOnDisabled;
                self.quick_stop_until_us = None;
            }
            self.app.controlword = cw;
            return;
        }
        if self.app.state == State::Fault && self.app.fault.is_some() && fault_reset_edge(cw, prev)
        {
            self.app.fault = None;
            self.push_emcy(emcy_code::NO_ERROR);
        }
        self.app.state = self
            .app
            .state
            .on_controlword(cw, prev, self.app.fault.is_some());
        self.app.controlword = cw;
    }

    /// Enabling touch probe 1 (again) clears its stored edges, as a real drive does,
    /// so each probing move latches afresh.
    fn apply_touch_probe_function(&mut self) {
        let f = TouchProbeFunction::from_bits(self.app.tp_function);
        let level = self.app.tp_status & TouchProbeStatus::INPUT_LEVEL;
        self.app.tp_status = level
            | if f.enabled(Probe::One) {
                TouchProbeStatus::ENABLED
            } else {
                0
            };
    }

    fn object_bits(index: u16, sub: u8) -> Option<u8> {
        Some(match (index, sub) {
            (obj::CONTROLWORD | obj::STATUSWORD | obj::ERROR_CODE, 0) => 16,
            (obj::TOUCH_PROBE_FUNCTION | obj::TOUCH_PROBE_STATUS, 0) => 16,
            (obj::MODES_OF_OPERATION | obj::MODES_OF_OPERATION_DISPLAY, 0) => 8,
            (
                obj::POSITION_ACTUAL_VALUE
                | obj::TARGET_POSITION
                | obj::TOUCH_PROBE_1_POSITIVE_EDGE,
                0,
            ) => 32,
            _ => return None,
        })
    }

    /// Whether `e` can go into a PDO of `direction`: an RPDO carries only what the
    /// master may write, a TPDO any process value; the length must be the object's.
    fn mappable(direction: PdoDirection, e: MapEntry) -> bool {
        let writable = matches!(
            e.index,
            obj::CONTROLWORD
                | obj::TARGET_POSITION
                | obj::MODES_OF_OPERATION
                | obj::TOUCH_PROBE_FUNCTION
        );
        Self::object_bits(e.index, e.sub) == Some(e.bits)
            && (direction == PdoDirection::Tpdo || writable)
    }

    fn pdo_mut(&mut self, index: u16) -> Option<&mut PdoParameters> {
        let c = &mut self.comm;
        c.rpdo
            .iter_mut()
            .chain(c.tpdo.iter_mut())
            .find(|p| p.handles(index))
    }
}

fn le(data: &[u8], n: usize) -> Result<u64, SdoAbortCode> {
    if data.len() < n {
        return Err(SdoAbortCode::LENGTH_TOO_LOW);
    }
    if data.len() > n {
        return Err(SdoAbortCode::LENGTH_TOO_HIGH);
    }
    let mut b = [0u8; 8];
    b[..n].copy_from_slice(&data[..n]);
    Ok(u64::from_le_bytes(b))
}

fn put(buf: &mut [u8], v: u64, n: usize) -> Result<usize, SdoAbortCode> {
    if buf.len() < n {
        return Err(SdoAbortCode::OUT_OF_MEMORY);
    }
    buf[..n].copy_from_slice(&v.to_le_bytes()[..n]);
    Ok(n)
}

/// A simple variable: only sub-index 0 exists.
fn var(sub: u8, v: u64, n: usize) -> Result<(u64, usize), SdoAbortCode> {
    if sub == 0 {
        Ok((v, n))
    } else {
        Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST)
    }
}

/// A write to a read-only simple variable.
fn read_only(sub: u8) -> Result<(), SdoAbortCode> {
    var(sub, 0, 0).and(Err(SdoAbortCode::READ_ONLY))
}

/// A COB-ID entry (0x1005, 0x1014): 11-bit identifier, no bits in 11..=28, no 29-bit
/// frames; a valid entry's identifier changes only through an invalid one (CiA 301).
fn cob_id_entry(old: u32, data: &[u8], reserved: u32) -> Result<u32, SdoAbortCode> {
    let v = le(data, 4)? as u32;
    if v & (COB_ID_EXTENDED | reserved | 0x1FFF_F800) != 0 {
        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
    }
    let both_valid = old & COB_ID_INVALID == 0 && v & COB_ID_INVALID == 0;
    if both_valid && (old & 0x7FF) != (v & 0x7FF) {
        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
    }
    Ok(v)
}

impl ObjectDictionary for Objects {
    fn read(&mut self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        if let Some(p) = self.pdo_mut(index) {
            return p.read(index, sub, buf);
        }
        let (v, n) = match index {
            obj::DEVICE_TYPE => var(sub, DEVICE_TYPE as u64, 4)?,
            obj::ERROR_REGISTER => var(sub, self.error_register() as u64, 1)?,
            obj::COB_ID_SYNC => var(sub, self.comm.sync_cob_id as u64, 4)?,
            obj::COMMUNICATION_CYCLE_PERIOD => var(sub, self.comm.cycle_period_us as u64, 4)?,
            obj::MANUFACTURER_DEVICE_NAME => {
                var(sub, 0, 0)?;
                buf.get_mut(..DEVICE_NAME.len())
                    .ok_or(SdoAbortCode::OUT_OF_MEMORY)?
                    .copy_from_slice(DEVICE_NAME);
                return Ok(DEVICE_NAME.len());
            }
            obj::COB_ID_EMCY => var(sub, self.comm.emcy_cob_id as u64, 4)?,
            obj::PRODUCER_HEARTBEAT_TIME => var(sub, self.comm.heartbeat_ms as u64, 2)?,
            obj::CONSUMER_HEARTBEAT_TIME => match sub {
                0 => (1, 1),
                1 => (self.comm.heartbeat_consumer as u64, 4),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::ABORT_CONNECTION_OPTION_CODE => {
                var(sub, self.app.abort_connection as u16 as u64, 2)?
            }
            obj::IDENTITY => match sub {
                0 => (4, 1),
                1 => (VENDOR_ID as u64, 4),
                2 => (PRODUCT_CODE as u64, 4),
                3 => (REVISION as u64, 4),
                4 => (self.node as u64, 4),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::SUPPORTED_DRIVE_MODES => var(sub, SUPPORTED_DRIVE_MODES as u64, 4)?,
            _ => match (self.mapped_value(index, 0), Self::object_bits(index, 0)) {
                (Some(v), Some(bits)) => var(sub, v, bits as usize / 8)?,
                _ => return Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
            },
        };
        put(buf, v, n)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        if let Some(p) = self.pdo_mut(index) {
            let direction = p.direction();
            return p.write(index, sub, data, |e| Self::mappable(direction, e));
        }
        match index {
            obj::DEVICE_TYPE
            | obj::ERROR_REGISTER
            | obj::MANUFACTURER_DEVICE_NAME
            | obj::SUPPORTED_DRIVE_MODES
            | obj::STATUSWORD
            | obj::MODES_OF_OPERATION_DISPLAY
            | obj::POSITION_ACTUAL_VALUE
            | obj::ERROR_CODE
            | obj::TOUCH_PROBE_STATUS
            | obj::TOUCH_PROBE_1_POSITIVE_EDGE => read_only(sub),
            obj::IDENTITY => match sub {
                0..=4 => Err(SdoAbortCode::READ_ONLY),
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::CONSUMER_HEARTBEAT_TIME => match sub {
                0 => Err(SdoAbortCode::READ_ONLY),
                1 => {
                    let v = le(data, 4)? as u32;
                    // Bits 24-31 are reserved; a node ID is 1..=127 (0 with time 0:
                    // the entry is off).
                    let node = (v >> 16) & 0xFF;
                    if v >> 24 != 0 || node > 127 || (node == 0 && v & 0xFFFF != 0) {
                        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                    }
                    self.comm.heartbeat_consumer = v;
                    self.consumer_restart = true;
                    Ok(())
                }
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::ABORT_CONNECTION_OPTION_CODE => {
                var(sub, 0, 0)?;
                let v = le(data, 2)? as u16 as i16;
                if !(abort_connection::NO_ACTION..=abort_connection::QUICK_STOP).contains(&v) {
                    return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                }
                self.app.abort_connection = v;
                Ok(())
            }
            obj::COB_ID_SYNC => {
                var(sub, 0, 0)?;
                // Bit 30 would make this drive the SYNC producer: it is not one.
                self.comm.sync_cob_id = cob_id_entry(self.comm.sync_cob_id, data, 1 << 30)?;
                Ok(())
            }
            obj::COB_ID_EMCY => {
                var(sub, 0, 0)?;
                self.comm.emcy_cob_id = cob_id_entry(self.comm.emcy_cob_id, data, 1 << 30)?;
                Ok(())
            }
            obj::COMMUNICATION_CYCLE_PERIOD => {
                var(sub, 0, 0)?;
                self.comm.cycle_period_us = le(data, 4)? as u32;
                Ok(())
            }
            obj::PRODUCER_HEARTBEAT_TIME => {
                var(sub, 0, 0)?;
                self.comm.heartbeat_ms = le(data, 2)? as u16;
                self.heartbeat_restart = true;
                Ok(())
            }
            obj::MODES_OF_OPERATION => {
                var(sub, 0, 0)?;
                let m = le(data, 1)? as u8 as i8;
                // This drive implements cyclic synchronous position only (0x6502).
                if m != CYCLIC_SYNCHRONOUS_POSITION {
                    return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                }
                self.app.mode = m;
                Ok(())
            }
            obj::CONTROLWORD | obj::TARGET_POSITION | obj::TOUCH_PROBE_FUNCTION => {
                var(sub, 0, 0)?;
                let bits = Self::object_bits(index, sub).unwrap_or(16);
                let v = le(data, bits as usize / 8)?;
                self.write_mapped(index, sub, v)
            }
            _ => Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
        }
    }
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

/// Most a heartbeat consumer's clock advances between two looks, µs. A host looks at
/// least every 50 ms (`SimRunner`), so while it runs the consumer keeps time.
const CONSUMER_LOOK_MAX_US: u64 = 100_000;

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

    /// Encoder position, increments.
    pub fn actual_inc(&self) -> i32 {
        self.od.actual
    }

    /// Where the drive will be at the end of the next step: the CSP target when it is
    /// enabled (one cycle of servo lag), else where it is.
    pub fn next_position_inc(&self) -> i32 {
        let a = &self.od.app;
        if a.state == State::OperationEnabled
            && a.mode == CYCLIC_SYNCHRONOUS_POSITION
            && a.fault.is_none()
        {
            a.target
        } else {
            self.od.actual
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
            tx(&heartbeat::boot_up(self.od.node));
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
        tx(&heartbeat::boot_up(node));
    }

    /// An RPDO arrived: event-driven data (254, 255) takes effect now, synchronous
    /// data (0..=240) at the next SYNC.
    fn on_rpdo(&mut self, i: usize, data: &[u8]) {
        let p = &self.od.comm.rpdo[i];
        let synchronous = p.transmission_type() <= 240;
        let map = p.mapping().clone();
        let Ok(values) = map.unpack(data) else {
            // A PDO of the wrong length: CiA 301 EMCY 0x8210, the data is not used.
            if !self.od.pdo_length_error {
                self.od.pdo_length_error = true;
                self.od.push_emcy(emcy_code::PDO_LENGTH_ERROR);
            }
            return;
        };
        if self.od.pdo_length_error {
            self.od.pdo_length_error = false;
            self.od.push_emcy(emcy_code::NO_ERROR);
        }
        if synchronous {
            let mut d = [0u8; 8];
            let n = data.len().min(8);
            d[..n].copy_from_slice(&data[..n]);
            self.rpdo_at_sync[i] = Some((d, n));
            return;
        }
        for (e, v) in map.entries().iter().zip(values) {
            let _ = self.od.write_mapped(e.index, e.sub, v);
        }
    }

    /// A SYNC arrived (before the step it starts): synchronous RPDO data received
    /// since the last one takes effect.
    pub fn on_sync(&mut self) {
        if self.silent {
            return;
        }
        for i in 0..PDOS {
            let Some((d, n)) = self.rpdo_at_sync[i].take() else {
                continue;
            };
            let map = self.od.comm.rpdo[i].mapping().clone();
            if let Ok(values) = map.unpack(&d[..n]) {
                for (e, v) in map.entries().iter().zip(values) {
                    let _ = self.od.write_mapped(e.index, e.sub, v);
                }
            }
        }
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

    /// 0x1016:1 as (node, consumer time ms).
    fn watched(&self) -> (u8, u16) {
        let v = self.od.comm.heartbeat_consumer;
        (((v >> 16) & 0x7F) as u8, v as u16)
    }

    /// A heartbeat (or boot-up) of `node`: if it is the watched one, it is alive; a
    /// reported loss is over (EMCY 0000).
    fn on_heartbeat(&mut self, node: u8) {
        self.restart_consumer_if_written();
        let (watched, ms) = self.watched();
        if ms == 0 || node != watched {
            return;
        }
        self.consumer.seen_us = Some(self.consumer.clock_us);
        self.consumer.lost = false;
        if self.od.heartbeat_lost {
            self.od.heartbeat_lost = false;
            // Error reset, unless a fault (0x6007 = 1) outlives the cause.
            if self.od.app.fault.is_none() {
                self.od.push_emcy(emcy_code::NO_ERROR);
            }
        }
    }

    /// 0x1016 was written (or reset): nothing is watched until the first heartbeat.
    fn restart_consumer_if_written(&mut self) {
        if self.od.consumer_restart {
            self.od.consumer_restart = false;
            self.consumer.seen_us = None;
            self.consumer.lost = false;
        }
    }

    /// The consumer looks at the time: the watched node silent for longer than the
    /// consumer time is a heartbeat event (CiA 301): EMCY 0x8130, then the reaction
    /// of 0x6007.
    fn consume_heartbeat(&mut self) {
        self.restart_consumer_if_written();
        let (node, ms) = self.watched();
        let c = &mut self.consumer;
        let step = c.looked_at_us.map_or(0, |t| self.now_us.saturating_sub(t));
        c.looked_at_us = Some(self.now_us);
        c.clock_us += step.min(u64::from(ms) * 500).min(CONSUMER_LOOK_MAX_US);
        let Some(seen) = c.seen_us else { return };
        let silent_us = c.clock_us - seen;
        if ms == 0 || c.lost || silent_us <= u64::from(ms) * 1000 {
            return;
        }
        c.lost = true;
        let from = self.od.app.state;
        self.od.heartbeat_lost = true;
        self.abort_connection();
        self.heartbeat_loss = Some((
            HeartbeatLoss {
                node,
                consumer_ms: ms,
                silent_us,
                at_us: self.now_us,
                from,
                to: self.od.app.state,
            },
            false,
        ));
    }

    /// The reaction of 0x6007 to a lost connection, with its EMCY 0x8130.
    fn abort_connection(&mut self) {
        let app = &mut self.od.app;
        match app.abort_connection {
            abort_connection::FAULT => {
                // Fault reaction: the EMCY carries the fault's own error register.
                app.fault.get_or_insert(emcy_code::HEARTBEAT_ERROR);
                app.state = State::Fault;
            }
            abort_connection::DISABLE_VOLTAGE if app.state != State::Fault => {
                app.state = State::SwitchOnDisabled;
            }
            abort_connection::QUICK_STOP => match app.state {
                // The axis stops where it is (the simulation brakes within a cycle),
                // then the drive is disabled.
                State::OperationEnabled | State::QuickStopActive => {
                    app.state = State::QuickStopActive;
                    self.od.quick_stop_until_us =
                        Some(self.now_us + u64::from(self.od.comm.cycle_period_us));
                }
                State::ReadyToSwitchOn | State::SwitchedOn => app.state = State::SwitchOnDisabled,
                _ => {}
            },
            _ => {}
        }
        self.od.push_emcy(emcy_code::HEARTBEAT_ERROR);
    }

    /// The quick stop of a lost connection is over: Switch on disabled.
    fn end_quick_stop(&mut self) {
        if let Some(until) = self.od.quick_stop_until_us {
            if self.now_us >= until {
                self.od.quick_stop_until_us = None;
                if self.od.app.state == State::QuickStopActive {
                    self.od.app.state = State::SwitchOnDisabled;
                }
            }
        }
    }

    /// The last loss of the watched heartbeat (0x1016), if any.
    pub fn heartbeat_loss(&self) -> Option<HeartbeatLoss> {
        self.heartbeat_loss.map(|(l, _)| l)
    }

    /// A loss not taken before (for the host's log), once.
    pub fn take_heartbeat_loss(&mut self) -> Option<HeartbeatLoss> {
        match &mut self.heartbeat_loss {
            Some((l, taken @ false)) => {
                *taken = true;
                Some(*l)
            }
            _ => None,
        }
    }

    fn produce_heartbeat(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        let period_us = u64::from(self.od.comm.heartbeat_ms) * 1000;
        if self.od.heartbeat_restart {
            self.od.heartbeat_restart = false;
            self.heartbeat_at_us = Some(self.now_us);
        }
        let Some(last) = self.heartbeat_at_us else {
            return;
        };
        if period_us == 0 || self.now_us < last + period_us {
            return;
        }
        // On the period's grid; after a stall of the host, one heartbeat, not a burst.
        let next = last + period_us;
        self.heartbeat_at_us = Some(if self.now_us >= next + period_us {
            self.now_us
        } else {
            next
        });
        tx(&heartbeat::encode(self.od.node, self.nmt));
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

    /// Starts a simulation step: remembers where the axis starts from.
    pub fn begin_step(&mut self) {
        self.step_from = self.od.actual;
    }

    /// Ends a step at `to_inc`. `latch_fraction`: the probe signal rose at this
    /// fraction of the step; `level`: the probe signal at the end of the step.
    /// Returns whether touch probe 1 latched in this step.
    pub fn end_step(&mut self, to_inc: i32, latch_fraction: Option<f64>, level: bool) -> bool {
        let mut latched = false;
        let app = &mut self.od.app;
        if let Some(frac) = latch_fraction {
            let f = TouchProbeFunction::from_bits(app.tp_function);
            let st = TouchProbeStatus::from_bits(app.tp_status);
            // First-event mode latches once until re-armed; continuous mode every edge.
            let room = !st.positive_edge_stored(Probe::One) || f.continuous(Probe::One);
            let armed = f.enabled(Probe::One) && f.sample_positive_edge(Probe::One) && room;
            if armed {
                let from = self.step_from as f64;
                let pos = from + frac * (to_inc as f64 - from);
                app.tp_pos_edge = pos.round() as i32;
                app.tp_status |= TouchProbeStatus::POSITIVE_EDGE_STORED;
                latched = true;
            }
        }
        if level {
            app.tp_status |= TouchProbeStatus::INPUT_LEVEL;
        } else {
            app.tp_status &= !TouchProbeStatus::INPUT_LEVEL;
        }
        self.od.actual = to_inc;
        latched
    }

    /// Puts the drive into Fault with an EMCY `code` (sent with the next answer).
    pub fn raise_fault(&mut self, code: u16) {
        if self.od.app.fault.is_none() {
            self.od.app.fault = Some(code);
            self.od.app.state = State::Fault;
            self.od.push_emcy(code);
        }
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

    /// `at_sync`: the synchronous TPDOs of this SYNC; else the event-driven ones that
    /// are due (data changed and the inhibit time over, or the event timer expired).
    /// Returns whether an event-driven TPDO changed but waits out its inhibit time.
    fn send_tpdos(&mut self, at_sync: bool, tx: &mut dyn FnMut(&CanFrame)) -> bool {
        let mut held = false;
        for i in 0..PDOS {
            let c = &self.od.comm.tpdo[i];
            if !c.is_enabled() {
                self.tpdo_syncs[i] = 0;
                continue;
            }
            let tt = c.transmission_type();
            let sync = tt <= 240;
            if sync != at_sync || (252..=253).contains(&tt) {
                continue;
            }
            let since_us = self.now_us.saturating_sub(self.sent_at_us[i]);
            let map = c.mapping();
            let mut values = [0u64; 8];
            for (v, e) in values.iter_mut().zip(map.entries()) {
                *v = self.od.mapped_value(e.index, e.sub).unwrap_or(0);
            }
            let (data, len) = map.pack(&values[..map.entries().len()]);
            let changed = self.last_sent[i] != Some((data, len));
            let send = match tt {
                0 => changed,
                1..=240 => {
                    self.tpdo_syncs[i] += 1;
                    let due = self.tpdo_syncs[i] >= tt;
                    if due {
                        self.tpdo_syncs[i] = 0;
                    }
                    due
                }
                _ => {
                    let inhibit_us = u64::from(c.inhibit_time_100us()) * 100;
                    let timer_us = u64::from(c.event_timer_ms()) * 1000;
                    held |= changed && since_us < inhibit_us;
                    (changed && since_us >= inhibit_us) || (timer_us > 0 && since_us >= timer_us)
                }
            };
            if !send {
                continue;
            }
            self.last_sent[i] = Some((data, len));
            self.sent_at_us[i] = self.now_us;
            if let Some(f) = CanFrame::new(c.cob_id(), &data[..len]) {
                tx(&f);
            }
        }
        held
    }
}
