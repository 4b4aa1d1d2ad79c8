//! The checks every backend makes before it moves anything, whatever the bus: the
//! request itself (feed, probing direction and distance), the software limits, and
//! the probing path plus the braking distance at the probing feed. A refused move
//! moves nothing. And the collision rule every backend applies while it moves: a probe
//! signal that rises during a positioning move means the stylus hit something.
//!
//! The guard is plain data built from the machine configuration; it does no I/O.

use crate::axis::{Axis, AxisPositions, MAX_AXES};
use crate::config::MachineConfig;
use crate::machine::{ErrorKind, MachineError, ProbeMove};

/// What the guard knows of one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
struct AxisBounds {
    min: f64,
    max: f64,
    /// Units/s^2.
    max_acceleration: f64,
    /// Units/min.
    max_feed: f64,
}

use crate::config::bounds::MIN_FEED;

/// The longest a single move may take at its feed (s): longer is a mistyped feed or
/// distance, refused before anything moves.
pub const MAX_MOVE_SECONDS: f64 = 15.0 * 60.0;

/// Software limits and braking of a machine's axes.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionGuard {
    axes: [Option<AxisBounds>; MAX_AXES],
}

/// A probing move the guard accepted: the direction as a unit vector, and the
/// distance the axes may travel beyond the path's end while they brake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckedProbe {
    pub direction: [f64; 3],
    pub braking_distance: f64,
}

impl MotionGuard {
    pub fn new(cfg: &MachineConfig) -> Self {
        let mut axes = [None; MAX_AXES];
        for a in &cfg.axes {
            axes[a.name.index()] = Some(AxisBounds {
                min: a.min,
                max: a.max,
                max_acceleration: a.max_acceleration,
                max_feed: a.max_feed,
            });
        }
        Self { axes }
    }

    /// The fastest feed of any axis (the rapid traverse).
    fn fastest(&self) -> f64 {
        self.axes
            .iter()
            .flatten()
            .map(|a| a.max_feed)
            .fold(0.0, f64::max)
    }

    /// A feed (mm/min, deg/min) must be finite, at least [`MIN_FEED`] and at most the
    /// fastest axis's `max_feed` (each axis is held to its own by the interpolation).
    pub fn check_feed(&self, feed: f64) -> Result<(), MachineError> {
        let fastest = self.fastest();
        if feed.is_finite() && (MIN_FEED..=fastest).contains(&feed) {
            Ok(())
        } else {
            Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "feed {feed} must be between {MIN_FEED} and the machine's fastest max_feed {fastest} (mm/min); nothing moved"
                ),
            ))
        }
    }

    /// A move of `distance` (mm or deg) at `feed` must end within
    /// [`MAX_MOVE_SECONDS`].
    pub fn check_duration(&self, distance: f64, feed: f64) -> Result<(), MachineError> {
        let seconds = distance / (feed / 60.0);
        if seconds.is_finite() && seconds <= MAX_MOVE_SECONDS {
            Ok(())
        } else {
            Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "a move of {distance:.3} at feed {feed} would take {seconds:.0} s, longer than {MAX_MOVE_SECONDS:.0} s; nothing moved"
                ),
            ))
        }
    }

    /// A straight move from `here` to `target` at `feed`: [`MotionGuard::check_move`]
    /// and its duration.
    pub fn check_move_from(
        &self,
        here: &AxisPositions,
        target: &AxisPositions,
        feed: f64,
    ) -> Result<(), MachineError> {
        self.check_move(target, feed)?;
        let mut sq = 0.0;
        for (axis, v) in target.iter() {
            if let Some(h) = here.get(axis) {
                sq += (v - h) * (v - h);
            }
        }
        self.check_duration(sq.sqrt(), feed)
    }

    /// Every axis of `target` exists and is inside its software limits. `what` names
    /// the move in the error ("move", "probing move").
    pub fn check_target(&self, target: &AxisPositions, what: &str) -> Result<(), MachineError> {
        for (axis, v) in target.iter() {
            let Some(a) = self.axes[axis.index()] else {
                return Err(MachineError::new(
                    ErrorKind::InvalidRequest,
                    format!("{what}: this machine has no {axis} axis"),
                ));
            };
            if !v.is_finite() || v < a.min || v > a.max {
                return Err(MachineError::new(
                    ErrorKind::SoftwareLimit,
                    format!(
                        "{what}: {axis}{v:+.4} is outside the software limits {:+.4} .. {:+.4}; nothing moved",
                        a.min, a.max
                    ),
                ));
            }
        }
        Ok(())
    }

    /// A straight move to `target` at `feed`: the feed and the target's limits.
    pub fn check_move(&self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.check_feed(feed)?;
        self.check_target(target, "move")
    }

    /// The distance the linear axes need to stop from `feed` (mm/min) along the unit
    /// vector `direction`, at the acceleration of the axis that needs longest.
    pub fn braking_distance(&self, direction: [f64; 3], feed: f64) -> f64 {
        let mut brake = 0.0f64;
        for (i, a) in Axis::LINEAR.iter().enumerate() {
            if let Some(b) = self.axes[a.index()] {
                let v = feed / 60.0 * direction[i].abs();
                brake = brake.max(v * v / (2.0 * b.max_acceleration));
            }
        }
        brake
    }

    /// The request of a probing move, before asking where the axes are: a non-zero
    /// direction (returned as a unit vector), feed and distance > 0.
    pub fn check_probe_request(&self, mv: &ProbeMove) -> Result<[f64; 3], MachineError> {
        let d = mv.direction;
        let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !(norm.is_finite() && norm > 1e-9) {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                "probing direction is zero",
            ));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(mv.feed) || !positive(mv.max_distance) {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "probing feed {} and distance {} must be > 0",
                    mv.feed, mv.max_distance
                ),
            ));
        }
        let unit = [d[0] / norm, d[1] / norm, d[2] / norm];
        // Each linear axis moves at feed x its share of the direction: none beyond
        // its max_feed (the latch must come at the feed asked for).
        let mut limit = f64::INFINITY;
        for (i, a) in Axis::LINEAR.iter().enumerate() {
            if let Some(b) = self.axes[a.index()] {
                if unit[i].abs() > 1e-9 {
                    limit = limit.min(b.max_feed / unit[i].abs());
                }
            }
        }
        if mv.feed < MIN_FEED || mv.feed > limit {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "probing feed {} must be between {MIN_FEED} and {limit:.0} mm/min (the axes' max_feed along this direction); nothing moved",
                    mv.feed
                ),
            ));
        }
        self.check_duration(mv.max_distance, mv.feed)?;
        Ok(unit)
    }

    /// A probing move from `here`: [`MotionGuard::check_probe_request`], and the path's
    /// end plus the braking distance inside the limits (the stop after a late contact
    /// runs on past the path).
    pub fn check_probe(
        &self,
        here: &AxisPositions,
        mv: &ProbeMove,
    ) -> Result<CheckedProbe, MachineError> {
        let direction = self.check_probe_request(mv)?;
        let braking_distance = self.braking_distance(direction, mv.feed);
        let mut end = *here;
        for (i, a) in Axis::LINEAR.iter().enumerate() {
            end.set(
                *a,
                here.get(*a).unwrap_or(0.0) + direction[i] * (mv.max_distance + braking_distance),
            );
        }
        self.check_target(&end, "probing move")?;
        Ok(CheckedProbe {
            direction,
            braking_distance,
        })
    }
}

/// May a positioning move start while the stylus is in contact (the probe signal
/// already high, so no rising edge will tell a collision)? Only out of the contact:
/// its linear part against `along`, the linear direction of the motion that made it (a
/// probing contact or a collision; `None` when it was there before anything moved, a
/// start inside material). `linear` is the move's X/Y/Z displacement; rotary axes may
/// turn while the linear axes lead the stylus out (cycle 451's retraction); a move that
/// goes nowhere may start.
pub fn may_start_deflected(along: Option<[f64; 3]>, linear: [f64; 3], rotary: bool) -> bool {
    if !rotary && linear.iter().all(|v| *v == 0.0) {
        return true;
    }
    along.is_some_and(|d| linear.iter().zip(d).map(|(m, d)| m * d).sum::<f64>() < 0.0)
}

/// The refusal of a positioning move that would push a stylus in contact further in
/// (see [`may_start_deflected`]), at `at` (machine X, Y, Z).
pub fn deflected_before_move(at: [f64; 3]) -> String {
    let [x, y, z] = at;
    format!(
        "the probe was already triggered at the start of the positioning move at X{x:+.4} Y{y:+.4} Z{z:+.4} (the stylus touches something: a start inside material?); only a retraction straight out of the contact may start like this; nothing moved. Retract by hand"
    )
}

/// The refusal of a probing move that would start with the probe signal high, at `at`.
pub fn deflected_before_probing(at: [f64; 3]) -> String {
    let [x, y, z] = at;
    format!(
        "the probe was already triggered at the start of the probing move at X{x:+.4} Y{y:+.4} Z{z:+.4} (the stylus touches something: a start inside material?); nothing moved"
    )
}

/// The probe input as a backend sees it cycle by cycle: tells a rising edge, which
/// during a positioning move (probe not armed) is a collision: brake all axes and
/// fail the move with [`ErrorKind::ProbeCollision`], without faulting the machine
/// (the operator retracts and goes on). Every axis sees the same probe, so no drive is
/// to blame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProbeInput {
    level: bool,
}

impl ProbeInput {
    /// Takes the input level; `true` when it just rose.
    pub fn update(&mut self, level: bool) -> bool {
        let rising = level && !self.level;
        self.level = level;
        rising
    }

    /// Is the probe deflected (the last level taken)?
    pub fn is_high(&self) -> bool {
        self.level
    }

    /// Is a rising input at this point a collision? Yes while positioning.
    pub fn is_collision(rising: bool, positioning: bool) -> bool {
        rising && positioning
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn guard() -> MotionGuard {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        MotionGuard::new(&MachineConfig::load(&p).unwrap())
    }

    #[test]
    fn targets_outside_the_limits_or_on_missing_axes_are_refused() {
        let g = guard();
        let e = g
            .check_target(&AxisPositions::linear([0.0, 0.0, 1.0e6]), "move")
            .unwrap_err();
        assert_eq!(e.kind, ErrorKind::SoftwareLimit);
        assert!(e.message.contains("nothing moved"), "{e}");
        let e = g
            .check_target(&AxisPositions::new().with(Axis::B, 0.0), "move")
            .unwrap_err();
        assert_eq!(e.kind, ErrorKind::InvalidRequest, "table-ac has no B: {e}");
        assert!(g.check_move(&AxisPositions::linear([0.0; 3]), 0.0).is_err());
        assert!(g
            .check_move(&AxisPositions::linear([0.0; 3]), 100.0)
            .is_ok());
    }

    #[test]
    fn the_probing_path_plus_the_braking_distance_must_fit() {
        let g = guard();
        let a = 2000.0; // table-ac's Z acceleration, mm/s^2
        let brake = g.braking_distance([0.0, 0.0, -1.0], 6000.0);
        // 100 mm/s: v^2 / 2a.
        assert!((brake - 100.0 * 100.0 / (2.0 * a)).abs() < 1e-9, "{brake}");
        let mv = |dist| ProbeMove {
            direction: [0.0, 0.0, -2.0],
            feed: 6000.0,
            max_distance: dist,
        };
        let p = guard()
            .check_probe(&AxisPositions::linear([0.0, 0.0, 100.0]), &mv(10.0))
            .unwrap();
        assert_eq!(p.direction, [0.0, 0.0, -1.0]);
        assert_eq!(p.braking_distance, brake);
        let e = g
            .check_probe(&AxisPositions::linear([0.0, 0.0, 0.0]), &mv(1.0e4))
            .unwrap_err();
        assert_eq!(e.kind, ErrorKind::SoftwareLimit);
        assert!(e.message.starts_with("probing move"), "{e}");
        let zero = ProbeMove {
            direction: [0.0; 3],
            ..mv(1.0)
        };
        assert_eq!(
            g.check_probe(&AxisPositions::linear([0.0; 3]), &zero)
                .unwrap_err()
                .kind,
            ErrorKind::InvalidRequest
        );
    }

    #[test]
    fn feeds_below_the_minimum_above_max_feed_or_too_slow_for_the_distance_are_refused() {
        let g = guard();
        let at = |x: f64, y: f64, z: f64| AxisPositions::linear([x, y, z]);
        let probe = |feed: f64, max_distance: f64| ProbeMove {
            direction: [0.0, 0.0, -1.0],
            feed,
            max_distance,
        };
        for feed in [0.000001, 0.5, 1e308, f64::NAN] {
            let e = g.check_probe_request(&probe(feed, 10.0)).unwrap_err();
            assert_eq!(e.kind, ErrorKind::InvalidRequest, "{feed}: {e}");
            let e = g.check_move(&at(0.0, 0.0, 10.0), feed).unwrap_err();
            assert_eq!(e.kind, ErrorKind::InvalidRequest, "{feed}: {e}");
        }
        let fastest = g.fastest();
        let e = g
            .check_probe_request(&probe(fastest * 2.0, 10.0))
            .unwrap_err();
        assert!(e.message.contains("max_feed"), "{e}");
        assert!(g.check_probe_request(&probe(100.0, 10.0)).is_ok());
        // 1 mm/min over 100 mm is 100 min: refused; over 10 mm, 10 min: fine.
        let e = g.check_probe_request(&probe(1.0, 100.0)).unwrap_err();
        assert!(e.message.contains("would take"), "{e}");
        assert!(g.check_probe_request(&probe(1.0, 10.0)).is_ok());
        let e = g
            .check_move_from(&at(0.0, 0.0, 0.0), &at(0.0, 0.0, 100.0), 1.0)
            .unwrap_err();
        assert!(e.message.contains("would take"), "{e}");
        assert!(g
            .check_move_from(&at(0.0, 0.0, 0.0), &at(0.0, 0.0, 100.0), 1000.0)
            .is_ok());
    }

    #[test]
    fn a_rising_probe_input_while_positioning_is_a_collision() {
        let mut p = ProbeInput::default();
        assert!(!p.update(false));
        assert!(p.update(true));
        assert!(!p.update(true), "a level, not an edge");
        assert!(ProbeInput::is_collision(true, true));
        assert!(!ProbeInput::is_collision(true, false), "probing: a contact");
    }
}
