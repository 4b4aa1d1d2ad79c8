//! Straight-line interpolation in machine coordinates with a trapezoidal velocity
//! profile: all axes start and arrive together, no axis exceeds its feed or
//! acceleration limit. Fixed-size, `Copy`, allocation-free: evaluated every cycle in the
//! real-time loop.

use crate::axis::MAX_AXES;

/// Per-axis limits in units/s and units/s^2 (mm or deg).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisLimits {
    pub max_velocity: [f64; MAX_AXES],
    pub max_acceleration: [f64; MAX_AXES],
}

impl AxisLimits {
    /// The limits of `machine`'s axes: `max_feed` (per minute) and `max_acceleration`;
    /// 0 for an axis it does not have.
    pub fn of(machine: &crate::config::MachineConfig) -> Self {
        let mut limits = AxisLimits {
            max_velocity: [0.0; MAX_AXES],
            max_acceleration: [0.0; MAX_AXES],
        };
        for a in &machine.axes {
            limits.max_velocity[a.name.index()] = a.max_feed / 60.0;
            limits.max_acceleration[a.name.index()] = a.max_acceleration;
        }
        limits
    }
}

/// A move along a straight line from `start` by `length` along the unit vector `dir`
/// (path units: mm when a linear axis moves, else deg).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Profile {
    start: [f64; MAX_AXES],
    dir: [f64; MAX_AXES],
    length: f64,
    /// Velocity at t = 0 (non-zero only for a stop).
    v0: f64,
    /// Cruise velocity and acceleration along the path.
    v: f64,
    a: f64,
    t_accel: f64,
    t_cruise: f64,
    t_decel: f64,
}

/// Path velocity and acceleration allowed along unit vector `dir` (per-axis limits
/// projected onto the path), and the path feed.
fn path_limits(dir: &[f64; MAX_AXES], feed_per_s: f64, limits: &AxisLimits) -> (f64, f64) {
    let mut v = feed_per_s;
    let mut a = f64::INFINITY;
    for ((u, vmax), amax) in dir
        .iter()
        .zip(limits.max_velocity)
        .zip(limits.max_acceleration)
    {
        let u = u.abs();
        if u > 1e-12 {
            v = v.min(vmax / u);
            a = a.min(amax / u);
        }
    }
    (v, a)
}

impl Profile {
    /// Standstill at `at`.
    pub fn hold(at: [f64; MAX_AXES]) -> Self {
        Self {
            start: at,
            dir: [0.0; MAX_AXES],
            length: 0.0,
            v0: 0.0,
            v: 0.0,
            a: 1.0,
            t_accel: 0.0,
            t_cruise: 0.0,
            t_decel: 0.0,
        }
    }

    /// From standstill at `from` to standstill at `to` at `feed` (units/min). The path
    /// length is measured over the linear axes when any of them moves (as a TNC does),
    /// otherwise over the rotary axes. `mask` marks the axes that exist.
    pub fn line(
        from: [f64; MAX_AXES],
        to: [f64; MAX_AXES],
        feed_per_min: f64,
        limits: &AxisLimits,
    ) -> Self {
        let mut delta = [0.0; MAX_AXES];
        for i in 0..MAX_AXES {
            delta[i] = to[i] - from[i];
        }
        let lin = (delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2]).sqrt();
        let rot = (delta[3] * delta[3] + delta[4] * delta[4] + delta[5] * delta[5]).sqrt();
        let length = if lin > 1e-9 { lin } else { rot };
        if length <= 1e-9 {
            return Self::hold(to);
        }
        let mut dir = [0.0; MAX_AXES];
        for i in 0..MAX_AXES {
            dir[i] = delta[i] / length;
        }
        let (mut v, a) = path_limits(&dir, feed_per_min / 60.0, limits);
        // Triangle profile when the line is too short to reach the feed.
        let t_accel;
        let t_cruise;
        if v * v / a > length {
            v = (length * a).sqrt();
            t_accel = v / a;
            t_cruise = 0.0;
        } else {
            t_accel = v / a;
            t_cruise = (length - v * v / a) / v;
        }
        Self {
            start: from,
            dir,
            length,
            v0: 0.0,
            v,
            a,
            t_accel,
            t_cruise,
            t_decel: t_accel,
        }
    }

    /// Total duration, s.
    pub fn duration(&self) -> f64 {
        self.t_accel + self.t_cruise + self.t_decel
    }

    /// The time at which the path has come `s` along (0 .. length; a start-stop
    /// profile, not a stop): when a probing move along it reaches its contact.
    pub fn time_at_distance(&self, s: f64) -> f64 {
        let s = s.clamp(0.0, self.length);
        let (a, v, ta, tc) = (self.a, self.v, self.t_accel, self.t_cruise);
        if self.length <= 0.0 {
            return 0.0;
        }
        let s_accel = 0.5 * a * ta * ta;
        if s <= s_accel {
            (2.0 * s / a).sqrt()
        } else if s <= s_accel + v * tc {
            ta + (s - s_accel) / v
        } else {
            let rest = s - s_accel - v * tc;
            ta + tc + (v - (v * v - 2.0 * a * rest).max(0.0).sqrt()) / a
        }
    }

    pub fn is_done(&self, t: f64) -> bool {
        t >= self.duration()
    }

    /// Distance along the path at time `t` (s since the profile started).
    fn distance(&self, t: f64) -> f64 {
        if self.length <= 0.0 {
            return 0.0;
        }
        let t = t.clamp(0.0, self.duration());
        if self.v0 > 0.0 {
            // Stopping profile: decelerate from v0.
            return self.v0 * t - 0.5 * self.a * t * t;
        }
        let (ta, tc) = (self.t_accel, self.t_cruise);
        if t <= ta {
            0.5 * self.a * t * t
        } else if t <= ta + tc {
            0.5 * self.a * ta * ta + self.v * (t - ta)
        } else {
            let td = t - ta - tc;
            0.5 * self.a * ta * ta + self.v * tc + self.v * td - 0.5 * self.a * td * td
        }
    }

    /// Path velocity at `t`.
    pub fn velocity(&self, t: f64) -> f64 {
        if self.length <= 0.0 || t >= self.duration() || t < 0.0 {
            return 0.0;
        }
        if self.v0 > 0.0 {
            return self.v0 - self.a * t;
        }
        let (ta, tc) = (self.t_accel, self.t_cruise);
        if t <= ta {
            self.a * t
        } else if t <= ta + tc {
            self.v
        } else {
            self.v - self.a * (t - ta - tc)
        }
    }

    /// Setpoint of every axis at `t`.
    pub fn position(&self, t: f64) -> [f64; MAX_AXES] {
        let s = self.distance(t);
        let mut p = self.start;
        for (pi, di) in p.iter_mut().zip(self.dir) {
            *pi += di * s;
        }
        p
    }

    /// The unit direction of the path (all axes).
    pub fn direction(&self) -> [f64; MAX_AXES] {
        self.dir
    }

    /// The end point.
    pub fn end(&self) -> [f64; MAX_AXES] {
        self.position(self.duration())
    }

    /// A profile that brings this one to rest as fast as the limits allow, starting
    /// from its state at `t`, along the same line.
    pub fn stop_at(&self, t: f64, limits: &AxisLimits) -> Self {
        let here = self.position(t);
        let v0 = self.velocity(t);
        if v0 <= 0.0 {
            return Self::hold(here);
        }
        let (_, a) = path_limits(&self.dir, f64::INFINITY, limits);
        let t_decel = v0 / a;
        Self {
            start: here,
            dir: self.dir,
            length: v0 * v0 / (2.0 * a),
            v0,
            v: v0,
            a,
            t_accel: 0.0,
            t_cruise: 0.0,
            t_decel,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> AxisLimits {
        AxisLimits {
            max_velocity: [100.0; MAX_AXES],
            max_acceleration: [1000.0; MAX_AXES],
        }
    }

    #[test]
    fn reaches_target_and_respects_limits() {
        let from = [0.0; MAX_AXES];
        let to = [30.0, 40.0, 0.0, 0.0, 0.0, 0.0];
        let p = Profile::line(from, to, 6000.0, &limits());
        let end = p.end();
        assert!((end[0] - 30.0).abs() < 1e-9 && (end[1] - 40.0).abs() < 1e-9);
        // Y has the larger share: 0.8 of the path; its 100/s limit caps the path at 125.
        // Feed 6000/min = 100/s is lower, so the path runs at 100. Y's 1000/s^2 caps the
        // path's acceleration at 1250, which Y then uses in full.
        let dt = 1e-3;
        let (mut before, mut prev) = (p.position(-dt), p.position(0.0));
        let (mut t, mut v_max, mut a_max) = (0.0, [0.0f64; MAX_AXES], [0.0f64; MAX_AXES]);
        while t < p.duration() + 2.0 * dt {
            t += dt;
            let q = p.position(t);
            for i in 0..MAX_AXES {
                v_max[i] = v_max[i].max((q[i] - prev[i]).abs() / dt);
                // A second difference is bounded by the largest acceleration times dt^2.
                a_max[i] = a_max[i].max((q[i] - 2.0 * prev[i] + before[i]).abs() / (dt * dt));
            }
            (before, prev) = (prev, q);
        }
        for i in 0..MAX_AXES {
            assert!(v_max[i] <= 100.0 + 1e-6, "axis {i}: velocity {}", v_max[i]);
            assert!(
                a_max[i] <= 1000.0 + 1e-3,
                "axis {i}: acceleration {}",
                a_max[i]
            );
        }
        // The limits are reached, not just respected: Y cruises at 80, accelerates at 1000.
        assert!((v_max[1] - 80.0).abs() < 1e-6, "{}", v_max[1]);
        assert!(a_max[1] > 990.0, "{}", a_max[1]);
    }

    #[test]
    fn the_time_at_a_distance_is_where_the_profile_is_then() {
        let l = limits();
        for to in [100.0, 0.1, 5.0] {
            let p = Profile::line([0.0; 6], [to, 0.0, 0.0, 0.0, 0.0, 0.0], 6000.0, &l);
            for k in 0..=10 {
                let s = to * f64::from(k) / 10.0;
                let t = p.time_at_distance(s);
                assert!((p.position(t)[0] - s).abs() < 1e-9, "{to}: {s} at {t}");
            }
            assert!((p.time_at_distance(to) - p.duration()).abs() < 1e-9);
        }
    }

    #[test]
    fn short_move_is_a_triangle() {
        let p = Profile::line([0.0; 6], [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 6000.0, &limits());
        assert!(p.velocity(p.duration() / 2.0) < 100.0);
        assert!((p.end()[0] - 0.1).abs() < 1e-12);
    }

    #[test]
    fn stop_brakes_within_distance() {
        let l = limits();
        let p = Profile::line([0.0; 6], [100.0, 0.0, 0.0, 0.0, 0.0, 0.0], 6000.0, &l);
        let s = p.stop_at(0.5, &l);
        let at = p.position(0.5)[0];
        // v = 100, a = 1000: 5 mm to stop.
        assert!((s.end()[0] - at - 5.0).abs() < 1e-9);
        assert_eq!(s.velocity(s.duration()), 0.0);
    }

    #[test]
    fn rotary_only_move_uses_degrees() {
        let p = Profile::line([0.0; 6], [0.0, 0.0, 0.0, 0.0, 0.0, 90.0], 3600.0, &limits());
        assert!((p.end()[5] - 90.0).abs() < 1e-9);
        assert!(p.duration() > 1.5);
    }
}
