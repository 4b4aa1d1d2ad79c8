//! The register map of the PLC face, as a codec without I/O: holding registers in,
//! holding registers out. Three blocks:
//!
//! - request block (`REQUEST_BASE`, written by the PLC in one FC16): request code,
//!   request sequence, program number, flags, 8 float parameters, PLC heartbeat;
//! - state block (`STATE_BASE`, read-only): acknowledge, state, bits, progress, error,
//!   point index, gateway heartbeat;
//! - result block (`RESULT_BASE`, read-only): the result sequence, the results as
//!   REAL (IEEE 754 single) and as scaled DINT, and the result sequence again. A PLC
//!   reading the block in several requests takes the results only when both copies
//!   equal its request sequence.
//! - uncertainty block (`UNCERT_BASE`, read-only, appended after the result block
//!   without moving it): the result sequence, the standard uncertainty (k = 1) of each
//!   result slot as REAL in the same slot order (NaN where the result has none: the
//!   errors before optimisation, the dispersions, a missing result), and the sequence
//!   again.
//! - calibration block (`CALIB_BASE`, read-only, appended after the uncertainty block
//!   without moving it): the result sequence, cycle 460's probe table row (R, CAL_OF1,
//!   CAL_OF2, L) as REAL and their standard uncertainties as REAL (NaN when the cycle
//!   the result block holds is not 460, or for a column it kept), and the sequence again.
//! - machine time block (`TIME_BASE`, read-only, appended after the calibration block
//!   without moving it): the request sequence, how long the run's cycles kept the
//!   machine (s, REAL) and its split (positioning, rotary, probing, standing), and the
//!   sequence again; written at the end of every run, whatever its outcome.
//!
//! Reads and writes must lie inside one block; writes only inside the request block.

use super::results::{slots, Quantity, ResultKey, ResultValues};
use cycles::machine_time::TimeSplit;

pub const REQUEST_BASE: u16 = 0;
pub const REQ_CODE: u16 = 0;
pub const REQ_SEQ: u16 = 1;
pub const REQ_PROGRAM: u16 = 2;
pub const REQ_FLAGS: u16 = 3;
pub const REQ_PARAMS: u16 = 4;
pub const REQ_PARAM_COUNT: usize = super::measurement::START_PARAMS;
pub const REQ_PLC_HEARTBEAT: u16 = 20;
/// A write that changes the sequence covers at least `REQUEST_BASE..REQ_REQUEST_END`.
pub const REQ_REQUEST_END: u16 = REQ_PARAMS + 2 * REQ_PARAM_COUNT as u16;
pub const REQUEST_LEN: u16 = 21;

pub const STATE_BASE: u16 = 32;
pub const ST_ACK_SEQ: u16 = 32;
pub const ST_ACK_CODE: u16 = 33;
pub const ST_REASON: u16 = 34;
pub const ST_STATE: u16 = 35;
pub const ST_BITS: u16 = 36;
pub const ST_PROGRESS: u16 = 37;
pub const ST_ERROR_KIND: u16 = 38;
pub const ST_ERROR_CODE: u16 = 39;
pub const ST_POINT: u16 = 40;
pub const ST_GATEWAY_HEARTBEAT: u16 = 41;
pub const ST_PROGRAM: u16 = 42;
pub const ST_CYCLE: u16 = 43;
pub const STATE_LEN: u16 = 16;

pub const RESULT_BASE: u16 = 64;
pub const RES_SEQ_HEAD: u16 = 64;
pub const RES_REAL: u16 = 65;
/// Result slots (see [`super::results::slots`]).
pub const SLOTS: usize = 66;
pub const RES_DINT: u16 = RES_REAL + 2 * SLOTS as u16;
pub const RES_SEQ_TAIL: u16 = RES_DINT + 2 * SLOTS as u16;
pub const RESULT_LEN: u16 = RES_SEQ_TAIL - RESULT_BASE + 1;

pub const UNCERT_BASE: u16 = RES_SEQ_TAIL + 1;
pub const UNC_SEQ_HEAD: u16 = UNCERT_BASE;
pub const UNC_REAL: u16 = UNC_SEQ_HEAD + 1;
pub const UNC_SEQ_TAIL: u16 = UNC_REAL + 2 * SLOTS as u16;
pub const UNCERT_LEN: u16 = UNC_SEQ_TAIL - UNCERT_BASE + 1;

pub use super::results::CAL_COLUMNS;
pub const CALIB_BASE: u16 = UNC_SEQ_TAIL + 1;
pub const CAL_SEQ_HEAD: u16 = CALIB_BASE;
pub const CAL_REAL: u16 = CAL_SEQ_HEAD + 1;
pub const CAL_UNC: u16 = CAL_REAL + 2 * CAL_COLUMNS.len() as u16;
pub const CAL_SEQ_TAIL: u16 = CAL_UNC + 2 * CAL_COLUMNS.len() as u16;
pub const CALIB_LEN: u16 = CAL_SEQ_TAIL - CALIB_BASE + 1;

/// The machine time block: the total and its four parts, REAL each.
pub const TIME_BASE: u16 = CAL_SEQ_TAIL + 1;
pub const TIME_SEQ_HEAD: u16 = TIME_BASE;
pub const TIME_TOTAL: u16 = TIME_SEQ_HEAD + 1;
pub const TIME_SPLIT: u16 = TIME_TOTAL + 2;
pub const TIME_SEQ_TAIL: u16 = TIME_SPLIT + 2 * 4;
pub const TIME_LEN: u16 = TIME_SEQ_TAIL - TIME_BASE + 1;

/// Register counts a single request may carry (Modbus application protocol 6.3/6.12).
pub const MAX_READ: u16 = 125;
pub const MAX_WRITE: u16 = 123;

/// The DINT that marks a missing or unrepresentable result.
pub const DINT_MISSING: i32 = i32::MIN;

/// Request flag: go on where a cycle asks for confirmation.
pub const FLAG_CONFIRM: u16 = 1;
pub const FLAGS_KNOWN: u16 = FLAG_CONFIRM;

/// Order of the two registers of a 32-bit value (bytes within a register are always
/// big-endian, as Modbus says).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordOrder {
    /// High word first ("ABCD").
    HighFirst,
    /// Low word first ("CDAB").
    LowFirst,
}

impl WordOrder {
    pub fn split(self, v: u32) -> [u16; 2] {
        let (hi, lo) = ((v >> 16) as u16, v as u16);
        match self {
            WordOrder::HighFirst => [hi, lo],
            WordOrder::LowFirst => [lo, hi],
        }
    }
    pub fn join(self, w: [u16; 2]) -> u32 {
        let (hi, lo) = match self {
            WordOrder::HighFirst => (w[0], w[1]),
            WordOrder::LowFirst => (w[1], w[0]),
        };
        (u32::from(hi) << 16) | u32::from(lo)
    }
}

/// A Modbus exception the map answers with (data, not an error of the server).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapException {
    IllegalDataAddress,
    IllegalDataValue,
}

/// What the PLC asks for (the request block decoded).
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    pub code: u16,
    pub seq: u16,
    pub program: u16,
    pub flags: u16,
    pub params: [f32; REQ_PARAM_COUNT],
    pub plc_heartbeat: u16,
}

/// What the state block shows.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StateView {
    pub ack_seq: u16,
    /// The request code echoed; bit 15 set: refused.
    pub ack_code: u16,
    pub reason: u16,
    pub state: u16,
    pub bits: u16,
    pub progress_permille: u16,
    pub error_kind: u16,
    pub error_code: u16,
    pub point: u16,
    pub program: u16,
    pub cycle: u16,
}

/// The register image of the PLC face.
#[derive(Clone, Debug)]
pub struct RegisterMap {
    regs: Vec<u16>,
    order: WordOrder,
    int_scale: f64,
}

impl RegisterMap {
    pub fn new(order: WordOrder, int_scale: f64) -> Self {
        let mut m = Self {
            regs: vec![0; usize::from(TIME_SEQ_TAIL) + 1],
            order,
            int_scale,
        };
        m.set_results(0, &ResultValues::new());
        m.set_machine_time(0, None);
        m
    }

    fn block_of(addr: u16, count: u16) -> Option<(u16, u16)> {
        let end = u32::from(addr) + u32::from(count);
        [
            (REQUEST_BASE, REQUEST_LEN),
            (STATE_BASE, STATE_LEN),
            (RESULT_BASE, RESULT_LEN),
            (UNCERT_BASE, UNCERT_LEN),
            (CALIB_BASE, CALIB_LEN),
            (TIME_BASE, TIME_LEN),
        ]
        .into_iter()
        .find(|&(base, len)| addr >= base && end <= u32::from(base) + u32::from(len))
    }

    /// FC3: `count` registers from `addr`.
    pub fn read(&self, addr: u16, count: u16) -> Result<Vec<u16>, MapException> {
        if count == 0 || count > MAX_READ {
            return Err(MapException::IllegalDataValue);
        }
        Self::block_of(addr, count).ok_or(MapException::IllegalDataAddress)?;
        let a = usize::from(addr);
        Ok(self.regs[a..a + usize::from(count)].to_vec())
    }

    /// FC6/FC16 into the request block; anything else is refused and changes nothing.
    /// A write that changes the request sequence must also write the code, the
    /// program, the flags and the parameters (registers 0..19): a new sequence never
    /// re-runs whatever an earlier write left there (IllegalDataValue otherwise).
    pub fn write(&mut self, addr: u16, values: &[u16]) -> Result<(), MapException> {
        let count = u16::try_from(values.len()).map_err(|_| MapException::IllegalDataValue)?;
        if count == 0 || count > MAX_WRITE {
            return Err(MapException::IllegalDataValue);
        }
        match Self::block_of(addr, count) {
            Some((REQUEST_BASE, _)) => {
                let a = usize::from(addr);
                let end = a + values.len();
                let seq = usize::from(REQ_SEQ);
                let new_seq = (a..end).contains(&seq) && values[seq - a] != self.regs[seq];
                if new_seq && (a > usize::from(REQ_CODE) || end < usize::from(REQ_REQUEST_END)) {
                    return Err(MapException::IllegalDataValue);
                }
                self.regs[a..a + values.len()].copy_from_slice(values);
                Ok(())
            }
            _ => Err(MapException::IllegalDataAddress),
        }
    }

    pub fn request(&self) -> Request {
        let r = &self.regs;
        let mut params = [0.0f32; REQ_PARAM_COUNT];
        for (i, p) in params.iter_mut().enumerate() {
            let a = usize::from(REQ_PARAMS) + 2 * i;
            *p = f32::from_bits(self.order.join([r[a], r[a + 1]]));
        }
        Request {
            code: r[usize::from(REQ_CODE)],
            seq: r[usize::from(REQ_SEQ)],
            program: r[usize::from(REQ_PROGRAM)],
            flags: r[usize::from(REQ_FLAGS)],
            params,
            plc_heartbeat: r[usize::from(REQ_PLC_HEARTBEAT)],
        }
    }

    pub fn set_state(&mut self, s: &StateView) {
        for (addr, v) in [
            (ST_ACK_SEQ, s.ack_seq),
            (ST_ACK_CODE, s.ack_code),
            (ST_REASON, s.reason),
            (ST_STATE, s.state),
            (ST_BITS, s.bits),
            (ST_PROGRESS, s.progress_permille),
            (ST_ERROR_KIND, s.error_kind),
            (ST_ERROR_CODE, s.error_code),
            (ST_POINT, s.point),
            (ST_PROGRAM, s.program),
            (ST_CYCLE, s.cycle),
        ] {
            self.regs[usize::from(addr)] = v;
        }
    }

    pub fn set_gateway_heartbeat(&mut self, v: u16) {
        self.regs[usize::from(ST_GATEWAY_HEARTBEAT)] = v;
    }

    /// Writes the results of the run of request `seq` (the cycle they come from is in
    /// the state block) (missing slots read NaN and [`DINT_MISSING`]) and their
    /// uncertainties (missing: NaN), the result sequence last at both ends of both
    /// blocks.
    pub fn set_results(&mut self, seq: u16, values: &ResultValues) {
        for (i, q) in slots().into_iter().enumerate() {
            let u = values.get(&ResultKey::Uncertainty(q.clone())).copied();
            let [a, b] = self.order.split(u.map_or(f32::NAN, |u| u as f32).to_bits());
            let r = usize::from(UNC_REAL) + 2 * i;
            self.regs[r] = a;
            self.regs[r + 1] = b;
            let v = values.get(&ResultKey::Value(q)).copied();
            let real = v.map_or(f32::NAN, |v| v as f32);
            let dint = v.map_or(DINT_MISSING, |v| self.scaled(v));
            let [a, b] = self.order.split(real.to_bits());
            let r = usize::from(RES_REAL) + 2 * i;
            self.regs[r] = a;
            self.regs[r + 1] = b;
            let [a, b] = self.order.split(dint as u32);
            let d = usize::from(RES_DINT) + 2 * i;
            self.regs[d] = a;
            self.regs[d + 1] = b;
        }
        for (i, name) in CAL_COLUMNS.iter().enumerate() {
            for (base, key) in [
                (CAL_REAL, ResultKey::Value(Quantity::named(name))),
                (CAL_UNC, ResultKey::Uncertainty(Quantity::named(name))),
            ] {
                let v = values.get(&key).map_or(f32::NAN, |v| *v as f32);
                let [a, b] = self.order.split(v.to_bits());
                let r = usize::from(base) + 2 * i;
                self.regs[r] = a;
                self.regs[r + 1] = b;
            }
        }
        for at in [
            RES_SEQ_HEAD,
            RES_SEQ_TAIL,
            UNC_SEQ_HEAD,
            UNC_SEQ_TAIL,
            CAL_SEQ_HEAD,
            CAL_SEQ_TAIL,
        ] {
            self.regs[usize::from(at)] = seq;
        }
    }

    /// Writes how long the run of request `seq` kept the machine (`None`: not known,
    /// NaN), the sequence last at both ends.
    pub fn set_machine_time(&mut self, seq: u16, time: Option<&TimeSplit>) {
        let values = time.map_or([f64::NAN; 5], |t| {
            [t.total(), t.positioning, t.rotary, t.probing, t.standing]
        });
        for (i, v) in values.into_iter().enumerate() {
            let [a, b] = self.order.split((v as f32).to_bits());
            let r = usize::from(TIME_TOTAL) + 2 * i;
            self.regs[r] = a;
            self.regs[r + 1] = b;
        }
        self.regs[usize::from(TIME_SEQ_HEAD)] = seq;
        self.regs[usize::from(TIME_SEQ_TAIL)] = seq;
    }

    fn scaled(&self, v: f64) -> i32 {
        let s = (v * self.int_scale).round();
        if s.is_finite() && s > f64::from(DINT_MISSING) && s <= f64::from(i32::MAX) {
            s as i32
        } else {
            DINT_MISSING
        }
    }

    /// The register at `addr` (tests, logs).
    pub fn get(&self, addr: u16) -> u16 {
        self.regs[usize::from(addr)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_the_documented_one() {
        assert_eq!(RES_DINT, 197);
        assert_eq!(RES_SEQ_TAIL, 329);
        assert_eq!(RESULT_LEN, 266);
        let names: Vec<String> = slots().iter().map(ToString::to_string).collect();
        assert_eq!(names.len(), SLOTS);
        assert_eq!(names[0], "Q141");
        assert_eq!(names[9], "Q150");
        assert_eq!(names[34], "Q175");
        assert_eq!(names[35], "Q183");
        assert_eq!(names[36], "before.EY0A");
        assert_eq!(names[51], "after.EY0A");
        assert_eq!(names[65], "after.EC0C");
        // The uncertainty block comes after, every earlier register where it was.
        assert_eq!(
            (UNCERT_BASE, UNC_REAL, UNC_SEQ_TAIL, UNCERT_LEN),
            (330, 331, 463, 134)
        );
        // So does the calibration block, after it.
        assert_eq!(
            (CALIB_BASE, CAL_REAL, CAL_UNC, CAL_SEQ_TAIL, CALIB_LEN),
            (464, 465, 473, 481, 18)
        );
        // And the machine time block after that.
        assert_eq!(
            (TIME_BASE, TIME_TOTAL, TIME_SPLIT, TIME_SEQ_TAIL, TIME_LEN),
            (482, 483, 485, 493, 12)
        );
    }

    #[test]
    fn golden_machine_time_block() {
        let mut m = RegisterMap::new(WordOrder::LowFirst, 10_000.0);
        // Before any run: NaN, sequence 0.
        assert_eq!(m.read(TIME_TOTAL, 2).unwrap(), vec![0, 0x7FC0]);
        let t = TimeSplit {
            positioning: 2.0,
            rotary: 0.5,
            probing: 0.25,
            standing: 0.0,
        };
        m.set_machine_time(7, Some(&t));
        // 2.75 = 0x4030_0000, 2.0 = 0x4000_0000, 0.5 = 0x3F00_0000, 0.25 = 0x3E80_0000.
        assert_eq!(
            m.read(TIME_BASE, TIME_LEN).unwrap(),
            vec![7, 0, 0x4030, 0, 0x4000, 0, 0x3F00, 0, 0x3E80, 0, 0, 7]
        );
        assert_eq!(
            m.read(CAL_SEQ_TAIL, 2),
            Err(MapException::IllegalDataAddress)
        );
        assert_eq!(
            m.write(TIME_TOTAL, &[1]),
            Err(MapException::IllegalDataAddress)
        );
    }

    #[test]
    fn golden_calibration_block() {
        let v = |n: &str| ResultKey::Value(Quantity::named(n));
        let values: ResultValues = [
            (v("R"), 2.5),
            (ResultKey::Uncertainty(Quantity::named("R")), 0.5),
            (v("CAL_OF1"), 0.25),
            (v("L"), -2.0),
        ]
        .into_iter()
        .collect();
        let mut m = RegisterMap::new(WordOrder::LowFirst, 10_000.0);
        m.set_results(5, &values);
        // 2.5f32 = 0x4020_0000, 0.25 = 0x3E80_0000, -2.0 = 0xC000_0000, low word first.
        let regs = m.read(CALIB_BASE, CALIB_LEN).unwrap();
        assert_eq!(
            regs,
            vec![
                5, 0, 0x4020, 0, 0x3E80, 0, 0x7FC0, 0,
                0xC000, // R, CAL_OF1, CAL_OF2 (kept: NaN), L
                0, 0x3F00, 0, 0x7FC0, 0, 0x7FC0, 0, 0x7FC0, // u of R only
                5
            ]
        );
        // Not in any result slot, and not readable across the blocks' border.
        assert!(slots()
            .iter()
            .all(|n| !CAL_COLUMNS.contains(&n.to_string().as_str())));
        assert_eq!(
            m.read(UNC_SEQ_TAIL, 2),
            Err(MapException::IllegalDataAddress)
        );
        assert_eq!(
            m.read(CAL_SEQ_TAIL, 2),
            Err(MapException::IllegalDataAddress)
        );
        // A run without 460: every column NaN.
        m.set_results(6, &ResultValues::new());
        assert_eq!(m.read(CAL_REAL, 2).unwrap(), vec![0, 0x7FC0]);
        assert_eq!((m.get(CAL_SEQ_HEAD), m.get(CAL_SEQ_TAIL)), (6, 6));
    }

    #[test]
    fn golden_uncertainties_in_the_slot_order() {
        let after = Quantity::ErrorAfter("EX0C".into());
        let values: ResultValues = [
            (ResultKey::Value(Quantity::named("Q158")), 5.0),
            (ResultKey::Uncertainty(Quantity::named("Q158")), 0.5),
            (ResultKey::Value(after.clone()), 0.012),
            (ResultKey::Uncertainty(after), 0.25),
        ]
        .into_iter()
        .collect();
        let mut m = RegisterMap::new(WordOrder::HighFirst, 10_000.0);
        m.set_results(9, &values);
        // Q158 is slot 17, after.EX0C slot 61; 0.5f32 = 0x3F00_0000, 0.25 = 0x3E80_0000.
        assert_eq!(m.read(UNC_REAL + 2 * 17, 2).unwrap(), vec![0x3F00, 0x0000]);
        assert_eq!(m.read(UNC_REAL + 2 * 61, 2).unwrap(), vec![0x3E80, 0x0000]);
        // No uncertainty: NaN; the results themselves stay where they were.
        assert_eq!(m.read(UNC_REAL, 2).unwrap(), vec![0x7FC0, 0x0000]);
        assert_eq!(m.read(RES_REAL + 2 * 17, 2).unwrap(), vec![0x40A0, 0x0000]);
        assert_eq!((m.get(UNC_SEQ_HEAD), m.get(UNC_SEQ_TAIL)), (9, 9));
        // One block per read: across the two it is refused.
        assert_eq!(
            m.read(RES_SEQ_TAIL, 2),
            Err(MapException::IllegalDataAddress)
        );
        assert!(m.read(UNCERT_BASE, 125).is_ok());
    }

    #[test]
    fn golden_request_block() {
        let mut m = RegisterMap::new(WordOrder::HighFirst, 10_000.0);
        // code 1, seq 7, program 451, flags 1, P1 = 1.5 (0x3FC0_0000), heartbeat 99.
        let mut block = vec![1, 7, 451, 1, 0x3FC0, 0x0000];
        block.resize(usize::from(REQUEST_LEN), 0);
        block[usize::from(REQ_PLC_HEARTBEAT)] = 99;
        m.write(REQUEST_BASE, &block).unwrap();
        let r = m.request();
        assert_eq!((r.code, r.seq, r.program, r.flags), (1, 7, 451, 1));
        assert_eq!(r.params[0], 1.5);
        assert_eq!(r.plc_heartbeat, 99);
        let mut low = RegisterMap::new(WordOrder::LowFirst, 10_000.0);
        low.write(REQ_PARAMS, &[0x0000, 0x3FC0]).unwrap();
        assert_eq!(low.request().params[0], 1.5);
    }

    #[test]
    fn golden_results_in_both_word_orders() {
        let values: ResultValues = [
            (ResultKey::Value(Quantity::named("Q158")), 5.0),
            (ResultKey::Value(Quantity::named("Q183")), -2.0),
        ]
        .into_iter()
        .collect();
        let mut m = RegisterMap::new(WordOrder::HighFirst, 10_000.0);
        m.set_results(42, &values);
        let q158 = RES_REAL + 2 * 17;
        // 5.0f32 = 0x40A0_0000; 5.0 x 10000 = 50000 = 0x0000_C350.
        assert_eq!(m.read(q158, 2).unwrap(), vec![0x40A0, 0x0000]);
        assert_eq!(m.read(RES_DINT + 2 * 17, 2).unwrap(), vec![0x0000, 0xC350]);
        // -2.0f32 = 0xC000_0000; -20000 = 0xFFFF_B1E0.
        assert_eq!(m.read(RES_REAL + 70, 2).unwrap(), vec![0xC000, 0x0000]);
        assert_eq!(m.read(RES_DINT + 70, 2).unwrap(), vec![0xFFFF, 0xB1E0]);
        // A missing slot: NaN and i32::MIN.
        assert_eq!(m.read(RES_REAL, 2).unwrap(), vec![0x7FC0, 0x0000]);
        assert_eq!(m.read(RES_DINT, 2).unwrap(), vec![0x8000, 0x0000]);
        assert_eq!(m.get(RES_SEQ_HEAD), 42);
        assert_eq!(m.get(RES_SEQ_TAIL), 42);
        let mut low = RegisterMap::new(WordOrder::LowFirst, 10_000.0);
        low.set_results(1, &values);
        assert_eq!(low.read(q158, 2).unwrap(), vec![0x0000, 0x40A0]);
        assert_eq!(
            low.read(RES_DINT + 2 * 17, 2).unwrap(),
            vec![0xC350, 0x0000]
        );
    }

    #[test]
    fn golden_state_block() {
        let mut m = RegisterMap::new(WordOrder::HighFirst, 10_000.0);
        m.set_state(&StateView {
            ack_seq: 7,
            ack_code: 0x8001,
            reason: 1,
            state: 1,
            bits: 0b1_0011,
            progress_permille: 500,
            error_kind: 0,
            error_code: 0,
            point: 12,
            program: 451,
            cycle: 0,
        });
        m.set_gateway_heartbeat(3);
        assert_eq!(
            m.read(STATE_BASE, 12).unwrap(),
            vec![7, 0x8001, 1, 1, 0b1_0011, 500, 0, 0, 12, 3, 451, 0]
        );
    }

    #[test]
    fn access_rules() {
        let mut m = RegisterMap::new(WordOrder::HighFirst, 10_000.0);
        use MapException::*;
        assert_eq!(m.read(0, 0), Err(IllegalDataValue));
        assert_eq!(m.read(RESULT_BASE, 126), Err(IllegalDataValue));
        assert!(m.read(RESULT_BASE, 125).is_ok());
        assert_eq!(m.read(REQUEST_LEN, 1), Err(IllegalDataAddress));
        assert_eq!(m.read(REQUEST_LEN - 1, 2), Err(IllegalDataAddress));
        assert_eq!(m.read(RES_SEQ_TAIL, 2), Err(IllegalDataAddress));
        assert!(m.read(RES_SEQ_TAIL, 1).is_ok());
        assert_eq!(m.write(STATE_BASE, &[1]), Err(IllegalDataAddress));
        assert_eq!(m.write(RES_SEQ_HEAD, &[1]), Err(IllegalDataAddress));
        assert_eq!(m.write(REQUEST_LEN - 1, &[1, 2]), Err(IllegalDataAddress));
        assert_eq!(m.write(0, &[]), Err(IllegalDataValue));
        assert_eq!(m.write(0, &[0; 124]), Err(IllegalDataValue));
        assert_eq!(m.request().code, 0, "a refused write changes nothing");
        assert!(m.write(REQ_PLC_HEARTBEAT, &[5]).is_ok());
        assert_eq!(m.request().plc_heartbeat, 5);
    }

    #[test]
    fn a_new_sequence_comes_only_with_the_whole_request() {
        use MapException::*;
        let mut m = RegisterMap::new(WordOrder::HighFirst, 1e4);
        let mut block = [0u16; REQUEST_LEN as usize];
        block[usize::from(REQ_CODE)] = 1;
        block[usize::from(REQ_SEQ)] = 1;
        block[usize::from(REQ_PROGRAM)] = 431;
        assert!(m.write(REQUEST_BASE, &block).is_ok());
        // FC6 to the sequence alone: refused, the sequence stays.
        assert_eq!(m.write(REQ_SEQ, &[2]), Err(IllegalDataValue));
        assert_eq!(m.request().seq, 1);
        // Code and sequence without the parameters: refused too.
        assert_eq!(m.write(REQ_CODE, &[1, 2]), Err(IllegalDataValue));
        let mut next = block;
        next[usize::from(REQ_SEQ)] = 2;
        assert_eq!(m.write(REQ_SEQ, &next[1..]), Err(IllegalDataValue));
        assert_eq!(m.request().seq, 1);
        // The same sequence again, alone, changes nothing and is taken.
        assert!(m.write(REQ_SEQ, &[1]).is_ok());
        // Registers 0..19 with a new sequence, without the heartbeat: taken.
        block[usize::from(REQ_SEQ)] = 2;
        assert!(m
            .write(REQUEST_BASE, &block[..usize::from(REQ_REQUEST_END)])
            .is_ok());
        assert_eq!(m.request().seq, 2);
    }
}
