//! SYNC (COB-ID 0x080): no data, or with a counter (CiA 301 object 0x1019 "synchronous
//! counter overflow value" 2..=240) one byte counting 1..=overflow.

use super::{check_data, cob_id, frame, DecodeError};
use crate::can::CanFrame;

const SERVICE: &str = "SYNC";

/// Highest counter overflow value CiA 301 allows.
pub const MAX_COUNTER: u8 = 240;

/// The SYNC frame without counter (`080#`).
pub fn encode() -> CanFrame {
    frame(cob_id::SYNC, &[])
}

/// The SYNC frame with counter byte `counter` (1..=240).
pub fn encode_with_counter(counter: u8) -> CanFrame {
    frame(cob_id::SYNC, &[counter])
}

/// `Ok(None)` for a SYNC without counter, `Ok(Some(c))` with counter.
pub fn decode(f: &CanFrame) -> Result<Option<u8>, DecodeError> {
    if f.cob_id() != cob_id::SYNC {
        return Err(DecodeError::WrongCobId {
            service: SERVICE,
            cob_id: f.cob_id(),
        });
    }
    check_data(SERVICE, f, 0, 1)?;
    match f.data().first() {
        None => Ok(None),
        Some(&c) if (1..=MAX_COUNTER).contains(&c) => Ok(Some(c)),
        Some(&c) => Err(DecodeError::InvalidValue {
            service: SERVICE,
            field: "counter",
            value: c.into(),
        }),
    }
}

/// Produces the SYNC frames; the caller decides when (once per communication cycle).
#[derive(Clone, Debug)]
pub struct SyncProducer {
    overflow: u8,
    next: u8,
}

impl SyncProducer {
    /// `counter_overflow` as in 0x1019: 0 or 1 = no counter (1 is reserved),
    /// 2..=240 = counter wrapping after this value; larger values are clamped to 240.
    pub fn new(counter_overflow: u8) -> Self {
        let overflow = match counter_overflow {
            0 | 1 => 0,
            v => v.min(MAX_COUNTER),
        };
        Self { overflow, next: 1 }
    }

    /// The next SYNC frame; advances the counter.
    pub fn next_frame(&mut self) -> CanFrame {
        if self.overflow == 0 {
            return encode();
        }
        let c = self.next;
        self.next = if c >= self.overflow { 1 } else { c + 1 };
        encode_with_counter(c)
    }

    /// CiA 301: the counter restarts at 1 when the node enters operational.
    pub fn reset_counter(&mut self) {
        self.next = 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counter_wraps_at_overflow() {
        let mut p = SyncProducer::new(3);
        let got: Vec<_> = (0..5).map(|_| decode(&p.next_frame()).unwrap()).collect();
        assert_eq!(got, [Some(1), Some(2), Some(3), Some(1), Some(2)]);
        let mut p = SyncProducer::new(0);
        assert_eq!(p.next_frame().data(), &[] as &[u8]);
    }

    #[test]
    fn rejects_bad_counter() {
        let f = CanFrame::new(0x080, &[0]).unwrap();
        assert!(decode(&f).is_err());
        let f = CanFrame::new(0x080, &[241]).unwrap();
        assert!(decode(&f).is_err());
        let f = CanFrame::new(0x080, &[1, 2]).unwrap();
        assert!(matches!(decode(&f), Err(DecodeError::WrongLength { .. })));
    }
}
