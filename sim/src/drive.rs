//! A simulated CiA 402 servo drive on CANopen, built on the same codec as the master
//! (`hal::canopen`, `hal::cia402`): an object dictionary behind an SDO server, NMT,
//! PDOs as the master maps them, heartbeat, EMCY, the drive state machine, cyclic
//! synchronous position with one cycle of servo lag, and touch probe 1 latching the
//! exact position at the instant the probe signal rises.
//!
//! Per SYNC a drive answers in a fixed order: heartbeat (when due), EMCY (when new),
//! event-driven TPDOs whose data changed, then the synchronous TPDOs. The master under
//! lockstep pacing relies on the synchronous TPDO1 being a drive's last frame.

use hal::can::CanFrame;
use hal::canopen::cob_id;
use hal::canopen::emcy::Emcy;
use hal::canopen::heartbeat;
use hal::canopen::nmt::{NmtCommand, NmtState};
use hal::canopen::object as obj;
use hal::canopen::pdo::{MapEntry, PdoMapping, COB_ID_INVALID};
use hal::canopen::sdo::{ObjectDictionary, SdoAbortCode, SdoServer};
use hal::cia402::{Probe, State, Statusword, TouchProbeFunction, TouchProbeStatus};

const PDOS: usize = 4;

#[derive(Clone, Copy, Debug)]
struct PdoComm {
    cob_id: u32,
    transmission: u8,
}

/// The drive's objects. Plain fields, `Copy` data only: SYNC processing allocates
/// nothing.
#[derive(Clone, Debug)]
struct Objects {
    node: u8,
    cycle_period_us: u32,
    heartbeat_ms: u16,
    mode: i8,
    controlword: u16,
    statusword: u16,
    target: i32,
    actual: i32,
    error_code: u16,
    tp_function: u16,
    tp_status: u16,
    tp_pos_edge: i32,
    rpdo_comm: [PdoComm; PDOS],
    rpdo_map: [PdoMapping; PDOS],
    tpdo_comm: [PdoComm; PDOS],
    tpdo_map: [PdoMapping; PDOS],
    /// Set when the master wrote 0x60B8 (through an RPDO or SDO).
    tp_function_written: bool,
}

const DEVICE_NAME: &[u8] = b"probebridge simulated CiA 402 drive";

impl Objects {
    fn new(node: u8) -> Self {
        let default_comm = |base: u16| PdoComm {
            cob_id: COB_ID_INVALID | (base as u32 + node as u32),
            transmission: 255,
        };
        Self {
            node,
            cycle_period_us: 2000,
            heartbeat_ms: 0,
            mode: 0,
            controlword: 0,
            statusword: State::SwitchOnDisabled.statusword_bits(),
            target: 0,
            actual: 0,
            error_code: 0,
            tp_function: 0,
            tp_status: 0,
            tp_pos_edge: 0,
            rpdo_comm: cob_id::RPDO_BASE.map(default_comm),
            rpdo_map: Default::default(),
            tpdo_comm: cob_id::TPDO_BASE.map(default_comm),
            tpdo_map: Default::default(),
            tp_function_written: false,
        }
    }

    /// Value of a mappable object as raw bits.
    fn mapped_value(&self, index: u16, sub: u8) -> Option<u64> {
        Some(match (index, sub) {
            (obj::CONTROLWORD, 0) => self.controlword as u64,
            (obj::STATUSWORD, 0) => self.statusword as u64,
            (obj::MODES_OF_OPERATION, 0) | (obj::MODES_OF_OPERATION_DISPLAY, 0) => {
                self.mode as u8 as u64
            }
            (obj::POSITION_ACTUAL_VALUE, 0) => self.actual as u32 as u64,
            (obj::TARGET_POSITION, 0) => self.target as u32 as u64,
            (obj::ERROR_CODE, 0) => self.error_code as u64,
            (obj::TOUCH_PROBE_FUNCTION, 0) => self.tp_function as u64,
            (obj::TOUCH_PROBE_STATUS, 0) => self.tp_status as u64,
            (obj::TOUCH_PROBE_1_POSITIVE_EDGE, 0) => self.tp_pos_edge as u32 as u64,
            _ => return None,
        })
    }

    /// Objects the master may write through an RPDO.
    fn write_mapped(&mut self, index: u16, sub: u8, v: u64) -> Result<(), SdoAbortCode> {
        match (index, sub) {
            (obj::CONTROLWORD, 0) => self.controlword = v as u16,
            (obj::TARGET_POSITION, 0) => self.target = v as u32 as i32,
            (obj::MODES_OF_OPERATION, 0) => self.mode = v as u8 as i8,
            (obj::TOUCH_PROBE_FUNCTION, 0) => {
                self.tp_function = v as u16;
                self.tp_function_written = true;
            }
            _ => return Err(SdoAbortCode::CANNOT_BE_MAPPED),
        }
        Ok(())
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

    fn pdo_slot(index: u16, base: u16) -> Option<usize> {
        let i = index.wrapping_sub(base) as usize;
        (i < PDOS).then_some(i)
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

impl ObjectDictionary for Objects {
    fn read(&mut self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        if let Some(i) = Self::pdo_slot(index, obj::RPDO_COMMUNICATION)
            .or(Self::pdo_slot(index, obj::TPDO_COMMUNICATION))
        {
            let c = if index < obj::TPDO_COMMUNICATION {
                self.rpdo_comm[i]
            } else {
                self.tpdo_comm[i]
            };
            return match sub {
                0 => put(buf, 2, 1),
                1 => put(buf, c.cob_id as u64, 4),
                2 => put(buf, c.transmission as u64, 1),
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            };
        }
        if let Some(i) =
            Self::pdo_slot(index, obj::RPDO_MAPPING).or(Self::pdo_slot(index, obj::TPDO_MAPPING))
        {
            let m = if index < obj::TPDO_MAPPING {
                &self.rpdo_map[i]
            } else {
                &self.tpdo_map[i]
            };
            return match sub {
                0 => put(buf, m.entries().len() as u64, 1),
                s => m
                    .entries()
                    .get(s as usize - 1)
                    .map_or(Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST), |e| {
                        put(buf, e.to_u32() as u64, 4)
                    }),
            };
        }
        match (index, sub) {
            (obj::DEVICE_TYPE, 0) => put(buf, 0x0002_0192, 4), // CiA 402 servo drive
            (obj::ERROR_REGISTER, 0) => put(buf, (self.error_code != 0) as u64, 1),
            (obj::MANUFACTURER_DEVICE_NAME, 0) => {
                buf.get_mut(..DEVICE_NAME.len())
                    .ok_or(SdoAbortCode::OUT_OF_MEMORY)?
                    .copy_from_slice(DEVICE_NAME);
                Ok(DEVICE_NAME.len())
            }
            (obj::COMMUNICATION_CYCLE_PERIOD, 0) => put(buf, self.cycle_period_us as u64, 4),
            (obj::PRODUCER_HEARTBEAT_TIME, 0) => put(buf, self.heartbeat_ms as u64, 2),
            _ => match (self.mapped_value(index, sub), Self::object_bits(index, sub)) {
                (Some(v), Some(bits)) => put(buf, v, bits as usize / 8),
                _ => Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
            },
        }
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        if let Some(i) = Self::pdo_slot(index, obj::RPDO_COMMUNICATION)
            .or(Self::pdo_slot(index, obj::TPDO_COMMUNICATION))
        {
            let rx = index < obj::TPDO_COMMUNICATION;
            let c = if rx {
                &mut self.rpdo_comm[i]
            } else {
                &mut self.tpdo_comm[i]
            };
            return match sub {
                1 => {
                    c.cob_id = le(data, 4)? as u32;
                    Ok(())
                }
                2 => {
                    c.transmission = le(data, 1)? as u8;
                    Ok(())
                }
                0 => Err(SdoAbortCode::READ_ONLY),
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            };
        }
        if let Some(i) =
            Self::pdo_slot(index, obj::RPDO_MAPPING).or(Self::pdo_slot(index, obj::TPDO_MAPPING))
        {
            let rx = index < obj::TPDO_MAPPING;
            let comm = if rx {
                self.rpdo_comm[i]
            } else {
                self.tpdo_comm[i]
            };
            // CiA 301: the mapping may only change while the PDO is disabled.
            if comm.cob_id & COB_ID_INVALID == 0 {
                return Err(SdoAbortCode::DEVICE_STATE);
            }
            let m = if rx {
                &mut self.rpdo_map[i]
            } else {
                &mut self.tpdo_map[i]
            };
            return match sub {
                0 => {
                    let n = le(data, 1)? as usize;
                    if n == 0 {
                        *m = PdoMapping::new();
                        Ok(())
                    } else if n == m.entries().len() {
                        Ok(())
                    } else {
                        Err(SdoAbortCode::VALUE_RANGE_EXCEEDED)
                    }
                }
                s => {
                    let e = MapEntry::from_u32(le(data, 4)? as u32);
                    if Self::object_bits(e.index, e.sub) != Some(e.bits) {
                        return Err(SdoAbortCode::CANNOT_BE_MAPPED);
                    }
                    if s as usize != m.entries().len() + 1 {
                        return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST);
                    }
                    m.push(e).map_err(|_| SdoAbortCode::PDO_LENGTH_EXCEEDED)
                }
            };
        }
        match (index, sub) {
            (obj::COMMUNICATION_CYCLE_PERIOD, 0) => {
                self.cycle_period_us = le(data, 4)? as u32;
                Ok(())
            }
            (obj::PRODUCER_HEARTBEAT_TIME, 0) => {
                self.heartbeat_ms = le(data, 2)? as u16;
                Ok(())
            }
            (obj::MODES_OF_OPERATION, 0) => {
                let m = le(data, 1)? as u8 as i8;
                // This drive implements cyclic synchronous position only.
                if m != 8 {
                    return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                }
                self.mode = m;
                Ok(())
            }
            (obj::CONTROLWORD, 0) | (obj::TARGET_POSITION, 0) | (obj::TOUCH_PROBE_FUNCTION, 0) => {
                let bits = Self::object_bits(index, sub).unwrap_or(16);
                let v = le(data, bits as usize / 8)?;
                self.write_mapped(index, sub, v)
            }
            (obj::STATUSWORD, 0)
            | (obj::POSITION_ACTUAL_VALUE, 0)
            | (obj::TOUCH_PROBE_STATUS, 0)
            | (obj::TOUCH_PROBE_1_POSITIVE_EDGE, 0) => Err(SdoAbortCode::READ_ONLY),
            _ => Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
        }
    }
}

/// One simulated drive.
#[derive(Clone, Debug)]
pub struct SimDrive {
    od: Objects,
    sdo: SdoServer,
    nmt: NmtState,
    state: State,
    prev_controlword: u16,
    /// Encoder position at the start of the current step (increments).
    step_from: i32,
    /// Active fault (EMCY error code), until reset.
    fault: Option<u16>,
    emcy_pending: Option<u16>,
    /// Last data sent per event-driven TPDO, to send only on change.
    last_event: [Option<([u8; 8], usize)>; PDOS],
    since_heartbeat_us: u64,
    /// Stops answering anything (a node that fell off the bus).
    pub silent: bool,
}

impl SimDrive {
    /// A drive at encoder position `position_inc`.
    pub fn new(node: u8, position_inc: i32) -> Self {
        let mut od = Objects::new(node);
        od.actual = position_inc;
        od.target = position_inc;
        Self {
            od,
            sdo: SdoServer::new(node),
            nmt: NmtState::PreOperational,
            state: State::SwitchOnDisabled,
            prev_controlword: 0,
            step_from: position_inc,
            fault: None,
            emcy_pending: None,
            last_event: [None; PDOS],
            since_heartbeat_us: 0,
            silent: false,
        }
    }

    pub fn node(&self) -> u8 {
        self.od.node
    }

    pub fn state(&self) -> State {
        self.state
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
        if self.state == State::OperationEnabled && self.od.mode == 8 && self.fault.is_none() {
            self.od.target
        } else {
            self.od.actual
        }
    }

    pub fn cycle_period_us(&self) -> u32 {
        self.od.cycle_period_us
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
                    }
                }
            }
            cob_id::CobKind::SdoRequest { node }
                if node == self.od.node && self.nmt != NmtState::Stopped =>
            {
                if let Some(r) = self.sdo.on_frame(f, &mut self.od) {
                    tx(&r);
                }
            }
            cob_id::CobKind::Rpdo { num, node }
                if node == self.od.node && self.nmt == NmtState::Operational =>
            {
                self.on_rpdo(num, f.data());
            }
            _ => {}
        }
    }

    fn on_nmt(&mut self, cmd: NmtCommand, tx: &mut dyn FnMut(&CanFrame)) {
        match cmd {
            NmtCommand::Start => self.nmt = NmtState::Operational,
            NmtCommand::Stop => self.nmt = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.nmt = NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                // Communication objects back to their defaults (CiA 301), then boot-up.
                let keep = (self.od.actual, self.od.cycle_period_us);
                let node = self.od.node;
                self.od = Objects::new(node);
                (self.od.actual, self.od.cycle_period_us) = keep;
                self.od.target = keep.0;
                self.sdo = SdoServer::new(node);
                self.last_event = [None; PDOS];
                self.state = if self.fault.is_some() {
                    State::Fault
                } else {
                    State::SwitchOnDisabled
                };
                self.nmt = NmtState::PreOperational;
                tx(&heartbeat::boot_up(node));
            }
        }
    }

    fn on_rpdo(&mut self, num: u8, data: &[u8]) {
        let i = num as usize - 1;
        if i >= PDOS || self.od.rpdo_comm[i].cob_id & COB_ID_INVALID != 0 {
            return;
        }
        let map = self.od.rpdo_map[i].clone();
        let Ok(values) = map.unpack(data) else {
            // A PDO of the wrong length: CiA 301 EMCY 0x8210, the data is not used.
            self.emcy_pending = Some(hal::canopen::emcy::code::PDO_LENGTH_ERROR);
            return;
        };
        for (e, v) in map.entries().iter().zip(values) {
            let _ = self.od.write_mapped(e.index, e.sub, v);
        }
        if self.od.tp_function_written {
            self.od.tp_function_written = false;
            self.apply_touch_probe_function();
        }
        let cw = self.od.controlword;
        self.state = self
            .state
            .on_controlword(cw, self.prev_controlword, self.fault.is_some());
        if self.state == State::SwitchOnDisabled
            && self.fault.is_some()
            && hal::cia402::controlword::fault_reset_edge(cw, self.prev_controlword)
        {
            self.fault = None;
            self.od.error_code = 0;
        }
        self.prev_controlword = cw;
    }

    /// Enabling touch probe 1 (again) clears its stored edges, as a real drive does,
    /// so each probing move latches afresh.
    fn apply_touch_probe_function(&mut self) {
        let f = TouchProbeFunction::from_bits(self.od.tp_function);
        let level = self.od.tp_status & TouchProbeStatus::INPUT_LEVEL;
        self.od.tp_status = level
            | if f.enabled(Probe::One) {
                TouchProbeStatus::ENABLED
            } else {
                0
            };
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
        if let Some(frac) = latch_fraction {
            let f = TouchProbeFunction::from_bits(self.od.tp_function);
            let st = TouchProbeStatus::from_bits(self.od.tp_status);
            // First-event mode latches once until re-armed; continuous mode every edge.
            let room = !st.positive_edge_stored(Probe::One) || f.continuous(Probe::One);
            let armed = f.enabled(Probe::One) && f.sample_positive_edge(Probe::One) && room;
            if armed {
                let from = self.step_from as f64;
                let pos = from + frac * (to_inc as f64 - from);
                self.od.tp_pos_edge = pos.round() as i32;
                self.od.tp_status |= TouchProbeStatus::POSITIVE_EDGE_STORED;
                latched = true;
            }
        }
        if level {
            self.od.tp_status |= TouchProbeStatus::INPUT_LEVEL;
        } else {
            self.od.tp_status &= !TouchProbeStatus::INPUT_LEVEL;
        }
        self.od.actual = to_inc;
        latched
    }

    /// Puts the drive into Fault with an EMCY `code` (sent with the next SYNC answer).
    pub fn raise_fault(&mut self, code: u16) {
        if self.fault.is_none() {
            self.fault = Some(code);
            self.od.error_code = code;
            self.emcy_pending = Some(code);
            self.state = State::Fault;
        }
    }

    /// Answers one SYNC (after [`Self::end_step`]): heartbeat when due, EMCY, event
    /// TPDOs that changed, then synchronous TPDOs.
    pub fn answer_sync(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        if self.silent {
            return;
        }
        self.od.statusword = self.state.statusword_bits() | Statusword::REMOTE;
        self.since_heartbeat_us += self.od.cycle_period_us as u64;
        if self.od.heartbeat_ms > 0 && self.since_heartbeat_us >= self.od.heartbeat_ms as u64 * 1000
        {
            self.since_heartbeat_us = 0;
            tx(&heartbeat::encode(self.od.node, self.nmt));
        }
        if let Some(code) = self.emcy_pending.take() {
            let e = Emcy {
                error_code: code,
                error_register: 1,
                manufacturer: [0; 5],
            };
            tx(&e.encode(self.od.node));
        }
        if self.nmt != NmtState::Operational {
            return;
        }
        for pass_sync in [false, true] {
            for i in 0..PDOS {
                let c = self.od.tpdo_comm[i];
                if c.cob_id & COB_ID_INVALID != 0 {
                    continue;
                }
                let sync = (1..=240).contains(&c.transmission);
                if sync != pass_sync {
                    continue;
                }
                let map = &self.od.tpdo_map[i];
                let mut values = [0u64; 8];
                for (v, e) in values.iter_mut().zip(map.entries()) {
                    *v = self.od.mapped_value(e.index, e.sub).unwrap_or(0);
                }
                let (data, len) = map.pack(&values[..map.entries().len()]);
                if !sync {
                    if self.last_event[i] == Some((data, len)) {
                        continue;
                    }
                    self.last_event[i] = Some((data, len));
                }
                if let Some(f) = CanFrame::new((c.cob_id & 0x7FF) as u16, &data[..len]) {
                    tx(&f);
                }
            }
        }
    }
}
