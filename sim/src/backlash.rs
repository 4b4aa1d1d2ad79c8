//! Backlash of a rotary axis: the mechanical angle follows the commanded (encoder)
//! angle with a dead band of width `b`, `mech = clamp(mech, cmd - b/2, cmd + b/2)`,
//! starting at `mech = cmd`. The encoder, and so the latched position, reads the
//! commanded angle; the physics uses the mechanical one.

/// Dead-band state of one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Backlash {
    width: f64,
    /// `None` until the first commanded angle is seen.
    mech: Option<f64>,
}

impl Backlash {
    /// `width` in deg (0 = none).
    pub fn new(width: f64) -> Self {
        Self { width, mech: None }
    }

    pub fn width(&self) -> f64 {
        self.width
    }

    /// Mechanical angle if the axis moved to `cmd` now, without changing the state.
    pub fn mechanical(&self, cmd: f64) -> f64 {
        let h = self.width / 2.0;
        self.mech.map_or(cmd, |m| m.clamp(cmd - h, cmd + h))
    }

    /// Moves the axis to `cmd` and returns the new mechanical angle. Exact for any
    /// monotonic move since the last update.
    pub fn update(&mut self, cmd: f64) -> f64 {
        let m = self.mechanical(cmd);
        self.mech = Some(m);
        m
    }

    /// Starts over with the mechanical angle at `cmd`.
    pub fn reset(&mut self, cmd: f64) {
        self.mech = Some(cmd);
    }

    /// Current mechanical angle, `None` before the first update.
    pub fn state(&self) -> Option<f64> {
        self.mech
    }
}
