//! What a cycle asks before it goes on: a typed question and the text the operator
//! reads. A face decides on what is asked ([`ConfirmKind`]), never on how the text is
//! worded.

/// What a cycle asks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ConfirmKind {
    /// Cycle 431 with Q281 = 2: its protocol is shown, and the program goes on only
    /// when it is confirmed.
    PlaneProtocol,
    /// Cycle 451: a kinematics correction larger than `maxModification`, written only
    /// when confirmed.
    KinematicsCorrection,
    /// Cycle 451 where an M function positions the rotary axes (`mStrobeRotAxPos`):
    /// they read 0 deg, and the measurement starts only when that is confirmed. The
    /// gateway's start request from the PLC (which positions them) is that confirmation.
    RotaryAtZero,
}

/// A question a cycle asks: what ([`ConfirmKind`]) and the text shown.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Confirmation {
    pub kind: ConfirmKind,
    pub text: String,
}

impl Confirmation {
    pub fn new(kind: ConfirmKind, text: impl Into<String>) -> Self {
        Confirmation {
            kind,
            text: text.into(),
        }
    }
}

impl std::fmt::Display for Confirmation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}
