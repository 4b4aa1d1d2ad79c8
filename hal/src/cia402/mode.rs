//! Modes of operation (0x6060 written, 0x6061 displayed), INTEGER8.

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(i8)]
pub enum ModeOfOperation {
    ProfilePosition = 1,
    ProfileVelocity = 3,
    Homing = 6,
    CyclicSynchronousPosition = 8,
    CyclicSynchronousVelocity = 9,
    CyclicSynchronousTorque = 10,
}

/// A mode value this project does not implement (or a manufacturer-specific one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("mode of operation {0} is not supported")]
pub struct UnsupportedMode(pub i8);

impl ModeOfOperation {
    pub const fn as_i8(self) -> i8 {
        self as i8
    }
}

impl TryFrom<i8> for ModeOfOperation {
    type Error = UnsupportedMode;
    fn try_from(v: i8) -> Result<Self, UnsupportedMode> {
        Ok(match v {
            1 => Self::ProfilePosition,
            3 => Self::ProfileVelocity,
            6 => Self::Homing,
            8 => Self::CyclicSynchronousPosition,
            9 => Self::CyclicSynchronousVelocity,
            10 => Self::CyclicSynchronousTorque,
            _ => return Err(UnsupportedMode(v)),
        })
    }
}

impl From<ModeOfOperation> for i8 {
    fn from(m: ModeOfOperation) -> i8 {
        m as i8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        for v in -128..=127i8 {
            if let Ok(m) = ModeOfOperation::try_from(v) {
                assert_eq!(m.as_i8(), v);
            }
        }
        assert_eq!(
            ModeOfOperation::try_from(8),
            Ok(ModeOfOperation::CyclicSynchronousPosition)
        );
        assert_eq!(ModeOfOperation::try_from(-1), Err(UnsupportedMode(-1)));
    }
}
