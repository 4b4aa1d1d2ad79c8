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
