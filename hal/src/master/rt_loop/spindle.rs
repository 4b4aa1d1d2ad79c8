//! What the master knows of the spindle's drive (profile position): enabled with the
//! axes, supervised like them, oriented on command (see `orient`).

use crate::cia402::controlword::Controlword;
use crate::config::SpindleConfig;
use crate::master::process_data::SPINDLE_REFRESH_CYCLES;

/// What the master knows of the spindle's drive.
#[derive(Clone, Copy, Debug)]
pub(super) struct SpindleLink {
    pub(super) node: u8,
    /// Increments per degree.
    pub(super) scale: f64,
    pub(super) statusword: u16,
    pub(super) actual_inc: i32,
    pub(super) seen_tpdo1: bool,
    pub(super) answered: bool,
    pub(super) silent: bool,
    pub(super) last_emcy: Option<u16>,
    pub(super) controlword: u16,
    pub(super) target_inc: i32,
    /// The RPDO1 last sent (controlword, target), and SYNC periods since.
    sent: Option<(u16, i32)>,
    since_sent: u32,
    /// Longest an oriented stop may take: a whole turn at the orienting speed, plus
    /// the loop's settle timeout.
    pub(super) orient_timeout_ns: u64,
    /// The modulo-one-turn position of [`SpindleConfig::increments`].
    pub(super) increments_per_turn: f64,
}

impl SpindleLink {
    pub(super) fn new(s: &SpindleConfig, settle_timeout_ns: u64) -> Self {
        let turn_s = 60.0 / s.orient_rpm;
        Self {
            node: s.node,
            scale: s.increments_per_degree,
            statusword: 0,
            actual_inc: 0,
            seen_tpdo1: false,
            answered: false,
            silent: false,
            last_emcy: None,
            controlword: Controlword::SHUTDOWN,
            target_inc: 0,
            sent: None,
            since_sent: 0,
            orient_timeout_ns: settle_timeout_ns + (turn_s * 1e9) as u64,
            increments_per_turn: 360.0 * s.increments_per_degree,
        }
    }

    pub(super) fn degrees(&self, inc: i32) -> f64 {
        f64::from(inc) / self.scale
    }

    /// Whether its RPDO1 goes out with this SYNC: always while enabling or orienting
    /// (`busy`), else when it changed or is due for a refresh; counted as sent.
    pub(super) fn rpdo1_due(&mut self, busy: bool) -> bool {
        let now = (self.controlword, self.target_inc);
        self.since_sent = self.since_sent.saturating_add(1);
        let due = busy || self.sent != Some(now) || self.since_sent >= SPINDLE_REFRESH_CYCLES;
        if due {
            self.sent = Some(now);
            self.since_sent = 0;
        }
        due
    }
}

/// Where an oriented stop is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum OrientStage {
    /// Bit 4 is high with the target: waiting for the acknowledge.
    SetPoint,
    /// Bit 4 is low again: waiting for target reached.
    Turning,
}
