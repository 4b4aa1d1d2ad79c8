//! The machine time a plan will take, from the moves it commands: each move with the
//! trapezoidal profile the real-time loop interpolates (`hal::motion::Profile`, the
//! axes' `max_feed` and `max_acceleration` from the machine file), each probing move
//! to its contact at the probe table's feed and its stop, and what each command costs
//! beside its motion (the loop's handshakes, arming the probes, settling), counted in
//! SYNC periods. Beside it the plan's lower bound: every positioning move at the axes'
//! limits, every probing distance at the probing feed, nothing standing.

use super::{moves_linear, TimeSplit};
use hal::axis::MAX_AXES;
use hal::config::{CanOpenBusConfig, MachineConfig};
use hal::motion::{AxisLimits, Profile};
use hal::AxisPositions;

/// SYNC periods a positioning command costs beyond its profile: the command taken at
/// the next SYNC, the last setpoint's answer and settling in the window, the reply.
/// Measured on the simulator (`cli_rerun` compares every shipped example), where the
/// drives follow at once.
const MOVE_PERIODS: f64 = 3.0;
/// SYNC periods a probing move costs beyond its motion: the position read before it,
/// arming the touch probes (disarm, enable, wait for armed), the latch frames and
/// settling after the stop, the reply.
const PROBE_PERIODS: f64 = 8.0;

/// The machine's axes as the real-time loop moves them.
#[derive(Clone, Debug)]
pub struct MotionModel {
    limits: AxisLimits,
    period_s: f64,
    /// The spindle's orientation speed (deg/s) and acceleration (deg/s²), if any.
    spindle: Option<(f64, f64)>,
}

impl MotionModel {
    pub fn new(machine: &MachineConfig) -> Self {
        let limits = AxisLimits::of(machine);
        let bus = machine.canopen_bus().unwrap_or(&CanOpenBusConfig::DEFAULT);
        MotionModel {
            limits,
            period_s: f64::from(bus.sync_period_us) * 1e-6,
            spindle: machine
                .spindle
                .as_ref()
                .map(|s| (s.orient_rpm * 6.0, s.orient_acceleration)),
        }
    }

    /// A positioning move from `from` (every axis) to `to` at `feed` (mm/min, deg/min
    /// when only rotary axes turn), s.
    pub fn move_s(&self, from: &AxisPositions, to: &AxisPositions, feed: f64) -> f64 {
        let p = Profile::line(from.raw(), from.merged(to).raw(), feed, &self.limits);
        p.duration() + MOVE_PERIODS * self.period_s
    }

    /// The same move at the axes' own limits, nothing standing.
    pub fn fastest_move_s(&self, from: &AxisPositions, to: &AxisPositions) -> f64 {
        Profile::line(
            from.raw(),
            from.merged(to).raw(),
            f64::INFINITY,
            &self.limits,
        )
        .duration()
    }

    /// A probing move along `direction` (unit, machine XYZ) at `feed` (mm/min) that
    /// touches after `distance` of its `max_distance`, until the axes stand, s.
    pub fn probe_s(&self, direction: [f64; 3], feed: f64, distance: f64, max_distance: f64) -> f64 {
        let mut end = [0.0; MAX_AXES];
        for i in 0..3 {
            end[i] = direction[i] * max_distance;
        }
        let p = Profile::line([0.0; MAX_AXES], end, feed, &self.limits);
        let t = p.time_at_distance(distance);
        t + p.stop_at(t, &self.limits).duration() + PROBE_PERIODS * self.period_s
    }

    /// An oriented spindle stop turning `degrees`, s (0 without a spindle).
    pub fn orient_s(&self, degrees: f64) -> f64 {
        let Some((v, a)) = self.spindle else {
            return 0.0;
        };
        let d = degrees.abs();
        let t = if v * v / a > d {
            2.0 * (d / a).sqrt()
        } else {
            v / a + d / v
        };
        t + MOVE_PERIODS * self.period_s
    }
}

/// The time a plan will take, built move by move as the plan runs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prediction {
    pub split: TimeSplit,
    /// The plan's lower bound, s.
    pub lower_bound_s: f64,
}

impl Prediction {
    /// A positioning move from `from` (every axis) to `to`.
    pub fn add_move(
        &mut self,
        model: &MotionModel,
        from: &AxisPositions,
        to: &AxisPositions,
        feed: f64,
    ) {
        let t = model.move_s(from, to, feed);
        if moves_linear(Some(from), to) {
            self.split.positioning += t;
        } else {
            self.split.rotary += t;
        }
        self.lower_bound_s += model.fastest_move_s(from, to);
    }

    /// A probing move touching after `distance`.
    pub fn add_probe(
        &mut self,
        model: &MotionModel,
        direction: [f64; 3],
        feed: f64,
        distance: f64,
        max_distance: f64,
    ) {
        self.split.probing += model.probe_s(direction, feed, distance, max_distance);
        self.lower_bound_s += distance / (feed / 60.0);
    }

    /// An oriented spindle stop turning `degrees`.
    pub fn add_orient(&mut self, model: &MotionModel, degrees: f64) {
        self.split.rotary += model.orient_s(degrees);
    }

    /// `self` then `other`.
    pub fn plus(&self, other: &Prediction) -> Prediction {
        Prediction {
            split: self.split.plus(&other.split),
            lower_bound_s: self.lower_bound_s + other.lower_bound_s,
        }
    }
}
