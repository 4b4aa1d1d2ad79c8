//! The moves a probing cycle (431, 444) will command, known from its parameters, the
//! probe and the datum before anything moves. `check` and `run` hold them against the
//! machine's motion guard, the same checks the machine makes before each move, so a
//! point outside the software limits, or a feed the axes cannot run, stops the program
//! before its first move rather than after the cycles before it.

use hal::motion_guard::MotionGuard;
use hal::{AxisPositions, ProbeMove};

/// One move of a cycle, in machine coordinates.
#[derive(Clone, Debug, PartialEq)]
pub enum PlannedMove {
    /// A positioning move of the axes `target` names, at `feed` (the probe's FMAX).
    Position {
        step: String,
        target: AxisPositions,
        feed: f64,
    },
    /// A probing move starting at `from` (machine XYZ), expected to touch after
    /// `nominal` of its `mv.max_distance` (at the nominal point).
    Probe {
        step: String,
        from: [f64; 3],
        mv: ProbeMove,
        nominal: f64,
    },
    /// The retraction after a probing move: `distance` back against its direction
    /// from wherever the contact is, at `feed`. Where that is depends on the contact:
    /// `bounds` are its targets for a contact at the start and at the end of the
    /// probing path, both held against the machine.
    Retract {
        step: String,
        distance: f64,
        bounds: [AxisPositions; 2],
        feed: f64,
    },
}

/// The first move the machine would refuse, as "STEP: why".
pub fn check_planned(moves: &[PlannedMove], guard: &MotionGuard) -> Result<(), String> {
    for m in moves {
        match m {
            PlannedMove::Position { step, target, feed } => guard
                .check_move(target, *feed)
                .map_err(|e| format!("{step}: {e}"))?,
            PlannedMove::Retract {
                step, bounds, feed, ..
            } => {
                for target in bounds {
                    guard
                        .check_move(target, *feed)
                        .map_err(|e| format!("{step}: {e}"))?;
                }
            }
            PlannedMove::Probe { step, from, mv, .. } => {
                guard
                    .check_target(&AxisPositions::linear(*from), "probing move start")
                    .map_err(|e| format!("{step}: {e}"))?;
                guard
                    .check_probe(&AxisPositions::linear(*from), mv)
                    .map_err(|e| format!("{step}: {e}"))?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hal::config::MachineConfig;
    use hal::Axis;
    use std::path::Path;

    fn guard() -> MotionGuard {
        let mut text = String::from("name = \"m\"\n");
        for (node, axis) in ["X", "Y", "Z"].into_iter().enumerate() {
            text.push_str(&format!(
                "[[axis]]\nname = \"{axis}\"\nnode = {}\nincrements_per_unit = 1000.0\nmin = -100.0\nmax = 100.0\nmax_feed = 5000.0\nmax_acceleration = 1000.0\n",
                node + 1
            ));
        }
        MotionGuard::new(&MachineConfig::parse(&text, Path::new("m.toml")).unwrap())
    }

    #[test]
    fn the_first_refused_move_is_named() {
        let ok = PlannedMove::Position {
            step: "moving to the safe height".into(),
            target: AxisPositions::new().with(Axis::Z, 50.0),
            feed: 1000.0,
        };
        let probe = |from: [f64; 3]| PlannedMove::Probe {
            step: "probing point 2".into(),
            from,
            mv: ProbeMove {
                direction: [0.0, 0.0, -1.0],
                feed: 100.0,
                max_distance: 20.0,
            },
            nominal: 10.0,
        };
        assert_eq!(
            check_planned(&[ok.clone(), probe([0.0, 0.0, 10.0])], &guard()),
            Ok(())
        );
        let e = check_planned(&[ok.clone(), probe([0.0, 0.0, -90.0])], &guard()).unwrap_err();
        assert!(
            e.starts_with("probing point 2: ")
                && e.contains("probing move: Z-110.0014")
                && e.contains("software limits"),
            "{e}"
        );
        let e = check_planned(&[probe([150.0, 0.0, 0.0])], &guard()).unwrap_err();
        assert!(e.contains("X+150.0000"), "{e}");
        let slow = PlannedMove::Position {
            step: "positioning".into(),
            target: AxisPositions::new().with(Axis::X, 0.0),
            feed: 0.01,
        };
        let e = check_planned(&[slow], &guard()).unwrap_err();
        assert!(
            e.starts_with("positioning: ") && e.contains("feed 0.01"),
            "{e}"
        );
    }
}
