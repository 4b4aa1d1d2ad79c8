//! The touch probe: true ball radius `R`, pre-travel `p`, noise `s`.
//!
//! The signal is high (deflected) while the ball centre is closer than the trigger
//! distance `R - p - n` to some artefact surface (or inside the material), where `n`
//! is a Gaussian sample (sigma `s`, drawn from the scenario seed, `n = 0` when
//! `s = 0`), one per contact: a new `n` is drawn each time the signal falls. A real
//! stylus ([`crate::stylus`]) deflects more or less depending on the direction in
//! which the contact pushes the ball: its trigger distance is `R - p(u) - n`, with `u`
//! the surface normal nearest to the ball centre, in the stylus frame.
//!
//! Two details keep one contact one edge:
//! - the signal falls only once the centre is `HYSTERESIS` beyond the trigger
//!   distance, so a move ending exactly on the trigger distance does not chatter;
//! - a new `n` that would put the centre (still near the surface after the release)
//!   back inside its trigger distance takes effect only once the centre has moved
//!   beyond it, so a release never re-triggers immediately.

use crate::artefact::Surface;
use crate::scenario::ProbeTruth;
use crate::stylus::Stylus;
use nalgebra::{Rotation3, Vector3};
use rand::rngs::SmallRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Release hysteresis, mm: far below any noise or resolution that matters.
pub const HYSTERESIS: f64 = 1e-6;

/// Probe state: noise source, current trigger distance, signal.
#[derive(Clone, Debug)]
pub struct Probe {
    ball_radius: f64,
    pretravel: f64,
    noise: Option<Normal<f64>>,
    rng: SmallRng,
    /// Trigger distance in force, `R - p - n`.
    trigger: f64,
    /// Trigger distance drawn at the last release, waiting for the centre to clear it.
    pending: Option<f64>,
    /// Signal; `None` until the first position is seen.
    high: Option<bool>,
    /// The real stylus: its pre-travel by direction.
    stylus: Stylus,
}

/// Fixed-point steps solving a contact whose trigger distance depends on where the
/// ball touches; the normal turns by far less than a µrad per step of it.
const DIRECTION_ITERATIONS: usize = 6;

impl Probe {
    pub fn new(truth: &ProbeTruth, seed: u64) -> Self {
        let noise = (truth.noise > 0.0)
            .then(|| Normal::new(0.0, truth.noise).expect("scenario validates noise"));
        let mut probe = Self {
            ball_radius: truth.ball_radius,
            pretravel: truth.pretravel,
            noise,
            rng: SmallRng::seed_from_u64(seed),
            trigger: 0.0,
            pending: None,
            high: None,
            stylus: Stylus::new(truth),
        };
        probe.trigger = probe.nominal_trigger() - probe.draw_noise();
        probe
    }

    pub fn ball_radius(&self) -> f64 {
        self.ball_radius
    }

    /// `R - p`: the trigger distance without noise.
    pub fn nominal_trigger(&self) -> f64 {
        self.ball_radius - self.pretravel
    }

    /// One noise sample, mm (0 without noise). Advances the noise stream.
    pub fn draw_noise(&mut self) -> f64 {
        match &self.noise {
            Some(n) => n.sample(&mut self.rng),
            None => 0.0,
        }
    }

    /// Trigger distance in force for the next contact, `R - p - n`.
    pub fn trigger_distance(&self) -> f64 {
        self.trigger
    }

    /// Signal state; `None` before the first position.
    pub fn is_high(&self) -> Option<bool> {
        self.high
    }

    pub fn stylus(&self) -> &Stylus {
        &self.stylus
    }

    /// Trigger distance for the ball centre at `c` (table frame): `R - p(u) - n`, with
    /// `u` the nearest surface's normal turned into the stylus frame by `to_stylus`.
    fn trigger_at<S: Surface + ?Sized>(
        &self,
        base: f64,
        surfaces: &S,
        c: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) -> f64 {
        base - self.extra_at(surfaces, c, to_stylus)
    }

    /// `p(u) - p` for the ball centre at `c`: 0 for an isotropic stylus.
    fn extra_at<S: Surface + ?Sized>(
        &self,
        surfaces: &S,
        c: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) -> f64 {
        if self.stylus.is_isotropic() {
            return 0.0;
        }
        self.stylus
            .extra_pretravel(&(to_stylus * surfaces.normal(c)))
    }

    /// Would the signal be high with the ball centre at `c` (table frame)? Pure: does
    /// not change the state.
    pub fn deflected_at<S: Surface + ?Sized>(
        &self,
        surfaces: &S,
        c: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) -> bool {
        let distance = surfaces.distance(c);
        let trigger = self.trigger_at(self.trigger, surfaces, c, to_stylus);
        match self.high {
            Some(true) => distance < trigger + HYSTERESIS,
            _ => distance < trigger,
        }
    }

    /// Takes the signal from a position without an edge (start of a simulation).
    pub fn reset<S: Surface + ?Sized>(
        &mut self,
        surfaces: &S,
        c: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) {
        self.high = None;
        self.high = Some(self.deflected_at(surfaces, c, to_stylus));
    }

    /// Where on the segment `c0 -> c1` the distance first falls through the trigger
    /// distance of the contact it makes: with a direction-dependent pre-travel the
    /// trigger distance at the entry point is found by fixed-point iteration.
    fn entry<S: Surface + ?Sized>(
        &self,
        surfaces: &S,
        c0: &Vector3<f64>,
        c1: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) -> Option<f64> {
        if self.stylus.is_isotropic() {
            return surfaces.first_entry(c0, c1, self.trigger);
        }
        let mut trigger = self.trigger_at(self.trigger, surfaces, c0, to_stylus);
        let mut t = surfaces.first_entry(c0, c1, trigger).or_else(|| {
            trigger = self.trigger_at(self.trigger, surfaces, c1, to_stylus);
            surfaces.first_entry(c0, c1, trigger)
        })?;
        for _ in 0..DIRECTION_ITERATIONS {
            let at = c0 + (c1 - c0) * t;
            let next = self.trigger_at(self.trigger, surfaces, &at, to_stylus);
            if next == trigger {
                break;
            }
            trigger = next;
            match surfaces.first_entry(c0, c1, trigger) {
                Some(x) => t = x,
                None => break,
            }
        }
        Some(t)
    }

    /// The ball centre moves on a straight segment from `c0` to `c1`. Returns the
    /// fraction in `[0, 1]` of the segment where the signal rises, if it does (a
    /// start inside the trigger distance while low, e.g. after a jump, rises at 0).
    /// A release is resolved at the segment end.
    /// `to_stylus` turns table-frame directions into the stylus frame (for the
    /// direction-dependent pre-travel).
    pub fn advance<S: Surface + ?Sized>(
        &mut self,
        surfaces: &S,
        c0: &Vector3<f64>,
        c1: &Vector3<f64>,
        to_stylus: &Rotation3<f64>,
    ) -> Option<f64> {
        let d0 = surfaces.distance(c0);
        let x0 = self.extra_at(surfaces, c0, to_stylus);
        let mut high = self.high.unwrap_or(d0 < self.trigger - x0);
        let mut edge = None;
        if !high {
            self.arm_pending(d0, x0);
            if d0 < self.trigger - x0 {
                edge = Some(0.0);
            } else {
                edge = self.entry(surfaces, c0, c1, to_stylus);
            }
            high = edge.is_some();
        }
        let d1 = surfaces.distance(c1);
        let x1 = self.extra_at(surfaces, c1, to_stylus);
        if high && d1 >= self.trigger - x1 + HYSTERESIS {
            high = false;
            self.release(d1, x1);
        } else if !high {
            self.arm_pending(d1, x1);
        }
        self.high = Some(high);
        edge
    }

    /// The signal fell with the centre at `distance` (where the stylus's pre-travel
    /// differs from `p` by `extra`): draw the next contact's noise.
    fn release(&mut self, distance: f64, extra: f64) {
        let next = self.nominal_trigger() - self.draw_noise();
        if next - extra <= distance {
            self.trigger = next;
            self.pending = None;
        } else {
            self.pending = Some(next);
        }
    }

    fn arm_pending(&mut self, distance: f64, extra: f64) {
        if let Some(next) = self.pending {
            if distance >= next - extra {
                self.trigger = next;
                self.pending = None;
            }
        }
    }
}
