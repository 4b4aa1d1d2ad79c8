//! Touch probe function (0x60B8) and status (0x60B9): probe 1 in the low byte,
//! probe 2 the same in the high byte. Latched positions are in 0x60BA..=0x60BD.

/// Which of the two touch probes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Probe {
    One,
    Two,
}

impl Probe {
    const fn shift(self) -> u16 {
        match self {
            Probe::One => 0,
            Probe::Two => 8,
        }
    }

    /// Object holding the position latched on the positive edge.
    pub const fn positive_edge_object(self) -> u16 {
        match self {
            Probe::One => crate::canopen::object::TOUCH_PROBE_1_POSITIVE_EDGE,
            Probe::Two => crate::canopen::object::TOUCH_PROBE_2_POSITIVE_EDGE,
        }
    }

    /// Object holding the position latched on the negative edge.
    pub const fn negative_edge_object(self) -> u16 {
        match self {
            Probe::One => crate::canopen::object::TOUCH_PROBE_1_NEGATIVE_EDGE,
            Probe::Two => crate::canopen::object::TOUCH_PROBE_2_NEGATIVE_EDGE,
        }
    }
}

/// What triggers the probe (function bits 2-3 / 10-11).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TriggerSource {
    /// The probe's own digital input (touch probe 1 / 2 input).
    ExternalInput = 0b00,
    /// The encoder zero pulse.
    ZeroPulse = 0b01,
    /// The source selected in 0x60D0.
    SourceObject = 0b10,
    Reserved = 0b11,
}

/// 0x60B8 touch probe function.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TouchProbeFunction(u16);

impl TouchProbeFunction {
    pub const ENABLE: u16 = 1 << 0;
    /// 1 = continuous, 0 = latch the first event only.
    pub const CONTINUOUS: u16 = 1 << 1;
    pub const TRIGGER_MASK: u16 = 0b11 << 2;
    pub const SAMPLE_POSITIVE_EDGE: u16 = 1 << 4;
    pub const SAMPLE_NEGATIVE_EDGE: u16 = 1 << 5;

    pub const fn from_bits(bits: u16) -> Self {
        Self(bits)
    }

    pub const fn bits(self) -> u16 {
        self.0
    }

    /// Probe 1: enabled, first event, external input, positive edge (0x0011): the
    /// setting for one probing move.
    pub const fn probe1_first_positive_edge() -> u16 {
        Self::ENABLE | Self::SAMPLE_POSITIVE_EDGE
    }

    const fn bit(self, p: Probe, b: u16) -> bool {
        self.0 & (b << p.shift()) != 0
    }

    pub const fn enabled(self, p: Probe) -> bool {
        self.bit(p, Self::ENABLE)
    }

    pub const fn continuous(self, p: Probe) -> bool {
        self.bit(p, Self::CONTINUOUS)
    }

    pub const fn trigger(self, p: Probe) -> TriggerSource {
        match (self.0 >> (p.shift() + 2)) & 0b11 {
            0b00 => TriggerSource::ExternalInput,
            0b01 => TriggerSource::ZeroPulse,
            0b10 => TriggerSource::SourceObject,
            _ => TriggerSource::Reserved,
        }
    }

    pub const fn sample_positive_edge(self, p: Probe) -> bool {
        self.bit(p, Self::SAMPLE_POSITIVE_EDGE)
    }

    pub const fn sample_negative_edge(self, p: Probe) -> bool {
        self.bit(p, Self::SAMPLE_NEGATIVE_EDGE)
    }

    /// This function with probe `p` set up as given (the other probe untouched).
    pub const fn with_probe(
        self,
        p: Probe,
        enable: bool,
        continuous: bool,
        trigger: TriggerSource,
        positive_edge: bool,
        negative_edge: bool,
    ) -> Self {
        let mut low = (trigger as u16) << 2;
        if enable {
            low |= Self::ENABLE;
        }
        if continuous {
            low |= Self::CONTINUOUS;
        }
        if positive_edge {
            low |= Self::SAMPLE_POSITIVE_EDGE;
        }
        if negative_edge {
            low |= Self::SAMPLE_NEGATIVE_EDGE;
        }
        let s = p.shift();
        Self(self.0 & !(0x00FF << s) | low << s)
    }
}

/// 0x60B9 touch probe status.
///
/// CiA 402 leaves bits 6-7 (14-15 for probe 2) user defined; this project uses
/// bit 7 (15) for the probe input level, so the master can refuse to start a probing
/// move with a probe already deflected.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TouchProbeStatus(u16);

impl TouchProbeStatus {
    pub const ENABLED: u16 = 1 << 0;
    pub const POSITIVE_EDGE_STORED: u16 = 1 << 1;
    pub const NEGATIVE_EDGE_STORED: u16 = 1 << 2;
    /// Project convention (user-defined bit): the probe input is active.
    pub const INPUT_LEVEL: u16 = 1 << 7;

    pub const fn from_bits(bits: u16) -> Self {
        Self(bits)
    }

    pub const fn bits(self) -> u16 {
        self.0
    }

    const fn bit(self, p: Probe, b: u16) -> bool {
        self.0 & (b << p.shift()) != 0
    }

    const fn set(self, p: Probe, b: u16, on: bool) -> Self {
        let m = b << p.shift();
        Self(if on { self.0 | m } else { self.0 & !m })
    }

    pub const fn enabled(self, p: Probe) -> bool {
        self.bit(p, Self::ENABLED)
    }

    pub const fn positive_edge_stored(self, p: Probe) -> bool {
        self.bit(p, Self::POSITIVE_EDGE_STORED)
    }

    pub const fn negative_edge_stored(self, p: Probe) -> bool {
        self.bit(p, Self::NEGATIVE_EDGE_STORED)
    }

    pub const fn input_level(self, p: Probe) -> bool {
        self.bit(p, Self::INPUT_LEVEL)
    }

    pub const fn probe1_enabled(self) -> bool {
        self.enabled(Probe::One)
    }

    pub const fn probe1_positive_stored(self) -> bool {
        self.positive_edge_stored(Probe::One)
    }

    pub const fn probe1_negative_stored(self) -> bool {
        self.negative_edge_stored(Probe::One)
    }

    pub const fn probe1_input_level(self) -> bool {
        self.input_level(Probe::One)
    }

    pub const fn with_enabled(self, p: Probe, on: bool) -> Self {
        self.set(p, Self::ENABLED, on)
    }

    pub const fn with_positive_edge_stored(self, p: Probe, on: bool) -> Self {
        self.set(p, Self::POSITIVE_EDGE_STORED, on)
    }

    pub const fn with_negative_edge_stored(self, p: Probe, on: bool) -> Self {
        self.set(p, Self::NEGATIVE_EDGE_STORED, on)
    }

    pub const fn with_input_level(self, p: Probe, on: bool) -> Self {
        self.set(p, Self::INPUT_LEVEL, on)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn function_bits() {
        assert_eq!(TouchProbeFunction::probe1_first_positive_edge(), 0x0011);
        let f = TouchProbeFunction::default().with_probe(
            Probe::Two,
            true,
            true,
            TriggerSource::SourceObject,
            false,
            true,
        );
        assert_eq!(f.bits(), 0x2B00);
        assert!(f.enabled(Probe::Two) && f.continuous(Probe::Two));
        assert!(!f.enabled(Probe::One));
        assert_eq!(f.trigger(Probe::Two), TriggerSource::SourceObject);
        assert!(f.sample_negative_edge(Probe::Two) && !f.sample_positive_edge(Probe::Two));
        let f = TouchProbeFunction::from_bits(0x0011);
        assert_eq!(f.trigger(Probe::One), TriggerSource::ExternalInput);
        assert!(f.enabled(Probe::One) && !f.continuous(Probe::One));
    }

    #[test]
    fn status_bits() {
        let s = TouchProbeStatus::default()
            .with_enabled(Probe::One, true)
            .with_positive_edge_stored(Probe::One, true)
            .with_input_level(Probe::Two, true);
        assert_eq!(s.bits(), 0x8003);
        assert!(s.positive_edge_stored(Probe::One) && !s.negative_edge_stored(Probe::One));
        assert!(s.input_level(Probe::Two) && !s.input_level(Probe::One));
    }
}
