//! One planner for every cycle's moves, used by `check` and by `run` before anything
//! moves: the cycle's own sequence runs on a [`PlanMachine`] (motion guard, sphere
//! followed through the rotary axes, exact contacts, a path check against every
//! sphere still possible), once for each geometry the cycle's documented tolerances
//! allow ([`World`]): the expected one and the extremes. A move that fails in any of
//! them stops the plan, and the message says in which ([`in_every_world`]), so what
//! `run` can meet from any start the docs allow, `check` has met.
//!
//! Why the extremes suffice: before the first contact the path check covers the
//! whole continuum at once (the union of the possible spheres is convex,
//! [`path`]); after it, each cycle's moves follow what it found, and what limits them
//! (the software limits, Q408 above the found centre, the reach of the points) grows
//! monotonically with how far the sphere stands from the expected place in each
//! direction, so the farthest geometry in each direction is the one that reaches a
//! limit first.

pub mod machine;
pub mod path;

pub use machine::PlanMachine;
pub use path::{first_touch, Sphere, SphereSet, PATH_STEP, TOUCH_TOLERANCE};

use nalgebra::Vector3;

/// One geometry the cycle may meet: the sphere as it stands there, and what makes it
/// differ from the one the block expects (`None`: the expected one).
#[derive(Clone, Debug, PartialEq)]
pub struct World {
    pub truth: Sphere,
    pub what: Option<String>,
}

/// Runs `plan` in every world (the expected one first, whose result is returned).
/// The first failure stops it; one in another world is passed to `explain` with what
/// that world is, to say when it happens.
pub fn in_every_world<T, E>(
    worlds: &[World],
    mut plan: impl FnMut(&World) -> Result<T, E>,
    explain: impl Fn(E, &str) -> E,
) -> Result<T, E> {
    let mut expected = None;
    for w in worlds {
        match (plan(w), &w.what) {
            (Ok(t), None) => expected = expected.or(Some(t)),
            (Ok(_), Some(_)) => {}
            (Err(e), None) => return Err(e),
            (Err(e), Some(what)) => return Err(explain(e, what)),
        }
    }
    Ok(expected.expect("the expected world is planned"))
}

/// `message` with the world it fails in: "MESSAGE when WHAT, a start the docs allow;
/// nothing moved".
pub fn when(message: &str, what: &str) -> String {
    let m = message.trim_end_matches("; nothing moved");
    format!("{m}, when {what} (a start the docs allow); nothing moved")
}

/// Where a start the docs allow puts the sphere: below the ball centre `start`
/// (machine X/Y/Z) along the tool axis, from Q320 + SET_UP (`clear`) below its pole
/// (expected) up to just below the ball, and up to `reach` off across the tool axis.
/// 451 and 460 plan their first contact against it ([`StartReach::worlds`]).
#[derive(Clone, Copy, Debug)]
pub struct StartReach {
    /// The ball centre at the start, machine X/Y/Z.
    pub start: Vector3<f64>,
    /// The working plane's main and minor axes and the tool axis (pointing away from
    /// the sphere), machine X/Y/Z, as the axes stand at the start.
    pub frame: [Vector3<f64>; 3],
    /// Q407 + R: the ball centre's distance from the sphere centre at a contact.
    pub rs: f64,
    /// Q320 + SET_UP.
    pub clear: f64,
    /// How far off across the tool axis the sphere centre may stand.
    pub reach: f64,
    /// How much larger than `rs` a sphere may be before the first contact shows it.
    pub dev: f64,
}

impl StartReach {
    /// Every sphere the start allows, the expected one first (`clear` below the pole),
    /// then each extreme alone (a start at two limits at once is beyond what the pole
    /// probe reaches): just below the ball, and `reach` off toward each side of the
    /// working plane; and the set of all of them a move before the first contact must
    /// keep off. `to_table` takes a machine point to the spheres' coordinates (table
    /// coordinates where the rotary axes turn the sphere).
    pub fn worlds(
        &self,
        to_table: impl Fn(Vector3<f64>) -> Vector3<f64>,
    ) -> (Vec<World>, SphereSet) {
        let [main, minor, n] = self.frame;
        let (rs, clear, reach) = (self.rs, self.clear, self.reach);
        let at = |off: Vector3<f64>, gap: f64| Sphere {
            centre: to_table(self.start + off - n * (rs + gap)),
            touch: rs,
        };
        let zero = Vector3::zeros();
        let mut worlds = vec![
            World {
                truth: at(zero, clear),
                what: None,
            },
            World {
                truth: at(zero, 0.0),
                what: Some(format!(
                    "the probe starts just above the sphere's pole (the sphere {clear:.4} mm higher than Q320 + SET_UP below the start)"
                )),
            },
        ];
        for w in [main, minor] {
            for sign in [1.0, -1.0] {
                worlds.push(World {
                    truth: at(w * (sign * reach), clear),
                    what: Some(format!(
                        "the sphere centre stands {reach:.4} mm off below the start toward {}",
                        toward(&(w * sign))
                    )),
                });
            }
        }
        let lowest = self.start - n * (rs + self.dev + clear);
        let base = to_table(lowest);
        let possible = SphereSet {
            base,
            axis: to_table(lowest + n) - base,
            length: clear + self.dev,
            radial: reach,
            touch: rs + self.dev,
        };
        (worlds, possible)
    }
}

/// A direction as the axis it points along ("+X"), or its components.
fn toward(v: &Vector3<f64>) -> String {
    for (i, name) in ["X", "Y", "Z"].iter().enumerate() {
        if v[i].abs() > 1.0 - 1e-9 {
            return format!("{}{name}", if v[i] > 0.0 { "+" } else { "-" });
        }
    }
    format!("X{:+.3} Y{:+.3} Z{:+.3}", v.x, v.y, v.z)
}
