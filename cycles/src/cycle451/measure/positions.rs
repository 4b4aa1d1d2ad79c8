//! The measuring positions of every planned axis and the moves between them: before
//! the rotary axes turn, the probe retracts to Q408 and over the preset, or (Q408 = 0)
//! to the lowest height that clears the sphere for every angle of the turn; it
//! approaches the sphere only after they stand at the measurement's angles.

use super::{Measure, Measured, Sphere};
use crate::error::CycleError;
use crate::kinematics::model::Angles;
use hal::{Axis, AxisPositions, Machine};

impl<M: Machine> Measure<'_, '_, M> {
    /// Every angle set the cycle commands, in order: from the start, each axis's
    /// reference and positions (from both sides with Q432), back to the start.
    fn cycle_path(&self) -> Vec<Angles> {
        let plan = self.plan;
        let mut path = vec![self.start];
        for ap in &plan.axes {
            let b = if plan.backlash_measured(ap) {
                plan.params.backlash
            } else {
                0.0
            };
            for &angle in std::iter::once(&0.0).chain(&ap.positions) {
                if b != 0.0 {
                    path.push(plan.angles(ap.axis, angle + b));
                    path.push(plan.angles(ap.axis, angle));
                    path.push(plan.angles(ap.axis, angle - b));
                }
                path.push(plan.angles(ap.axis, angle));
            }
        }
        path.push(self.start);
        path
    }

    /// The tool-axis coordinate of the X/Y/Z axes at which the ball passes `gap`
    /// from the sphere centre (or more) along the tool axis at every angle the rotary
    /// axes take on the straight way through `path` (sampled every degree).
    pub(super) fn clear_height(&self, path: &[Angles], gap: f64) -> f64 {
        let t = self.tool.tool_index();
        let mut high = f64::NEG_INFINITY;
        for w in path.windows(2).chain(std::iter::once(&path[..1])) {
            let (from, to) = (w[0], *w.last().expect("one angle"));
            let turn = (0..3).map(|s| (to[s] - from[s]).abs()).fold(0.0, f64::max);
            let steps = (turn.ceil() as usize).max(1);
            for i in 0..=steps {
                let f = i as f64 / steps as f64;
                let a: Angles = std::array::from_fn(|s| from[s] + (to[s] - from[s]) * f);
                high = high.max(self.model.predict(&a, &self.table_point)[t] + gap);
            }
        }
        high
    }

    /// Measures every planned axis: the 0 deg reference, then its positions (from both
    /// sides with Q432), and goes back to where the cycle started.
    pub fn measure_axes(&mut self) -> Result<Measured, CycleError> {
        let plan = self.plan;
        let mut measured = Vec::new();
        for (gi, ap) in plan.axes.iter().enumerate() {
            let b = if plan.backlash_measured(ap) {
                plan.params.backlash
            } else {
                0.0
            };
            if plan.params.backlash != 0.0 && ap.hirth > 0.0 {
                self.notes.push(format!(
                    "{}: no backlash measurement on a Hirth axis",
                    ap.axis
                ));
            }
            let mut positions = Vec::new();
            for (k, &angle) in std::iter::once(&0.0).chain(&ap.positions).enumerate() {
                let what = if k == 0 {
                    format!("{} reference at 0 deg", ap.axis)
                } else {
                    format!("{} position {k} ({}{angle:+.4})", ap.axis, ap.axis)
                };
                self.note(format!("measuring {what}"));
                let spheres = self.position(ap.axis, angle, b, &what)?;
                positions.push((k == 0, spheres));
            }
            measured.push((gi, positions));
        }
        // Back to where the cycle started, over the sphere.
        self.go_to(self.start, None)?;
        Ok(measured)
    }

    /// The sphere(s) at one position of `axis`: approached from `angle + b` and from
    /// `angle - b` when `b != 0` (Q432), else directly.
    fn position(
        &mut self,
        axis: Axis,
        angle: f64,
        b: f64,
        what: &str,
    ) -> Result<Vec<Sphere>, CycleError> {
        let plan = self.plan;
        let target = plan.angles(axis, angle);
        let sides: Vec<Option<f64>> = if b != 0.0 {
            vec![Some(b), Some(-b)]
        } else {
            vec![None]
        };
        let unmoved = (0..3).all(|s| (target[s] - self.now[s]).abs() <= 1e-9);
        if b == 0.0 && unmoved {
            if let Some(s) = self.located.take() {
                // Nothing moved since the sphere was located there: that is this
                // position's measurement.
                self.note(format!(
                    "{what}: the locating measurement at the same angles is the reference"
                ));
                return Ok(vec![s]);
            }
        }
        self.located = None;
        let mut spheres = Vec::new();
        for side in &sides {
            let via = side.map(|off| plan.angles(axis, angle + off));
            // Each side its own turn at the height that clears the sphere (or Q408):
            // the second side's turn through `angle - b` is no shorter a swing.
            self.go_to(target, via)?;
            let expected = self.model.predict(&target, &self.table_point);
            let label = match side {
                Some(off) => format!(
                    "{what}, approached from {}",
                    if *off > 0.0 { "above" } else { "below" }
                ),
                None => what.to_string(),
            };
            let mut s = self.sphere(&target, expected, &label)?;
            s.record.approach = side.map(|off| if off > 0.0 { "above" } else { "below" }.into());
            spheres.push(s);
        }
        Ok(spheres)
    }

    /// Goes to the pole start at `to`, approaching `to` from `via` (backlash). The
    /// rotary axes turn only while the probe stands at a height that clears the sphere
    /// for every angle on the way: Q408 above the preset (and over the preset) when
    /// Q408 > 0, else the lowest height that clears it by Q320 + SET_UP along the tool
    /// axis at every angle of this turn (or higher, where the probe already stands).
    /// The approach (over the pole start at that height, then down to it) starts only
    /// after they stand at `to`.
    pub(super) fn go_to(&mut self, to: Angles, via: Option<Angles>) -> Result<(), CycleError> {
        let moves = (0..3).any(|s| (to[s] - self.now[s]).abs() > 1e-9) || via.is_some();
        if !moves {
            let pole = self.predicted_pole(&to);
            return self.approach_xyz("moving over the sphere", pole);
        }
        let t = self.tool.tool_index();
        let turn: Vec<Angles> = std::iter::once(self.now)
            .chain(via)
            .chain(std::iter::once(to))
            .collect();
        let h = self.plan.params.retract_height;
        let height = if h > 0.0 {
            self.retract_to_q408(&turn)?
        } else {
            let here = self.here()?;
            let pole = self.predicted_pole(&to);
            let clear = self.clear_height(&turn, self.reach());
            self.turn_height_in_limits(&turn, clear)?;
            let height = clear.max(pole[t]).max(here[t]);
            let up = AxisPositions::new().with(Axis::LINEAR[t], height);
            self.mv(
                "moving up to clear the sphere before the rotary axes turn",
                up,
                self.plan.rapid_feed,
            )?;
            height
        };
        for a in via.iter().chain(std::iter::once(&to)) {
            let step = if h > 0.0 {
                "turning the rotary axes (Q253)"
            } else {
                "turning the rotary axes at a height that clears the sphere (Q253)"
            };
            self.turn_rotary(step, a)?;
            self.now = *a;
        }
        let pole = self.predicted_pole(&to);
        if pole[t] > height {
            return Err(CycleError::Plan(format!(
                "Q408: the retraction height {height:.3} ({h} above the preset) is below the probe's start point over the sphere ({:.3}) at {}; give a higher Q408",
                pole[t],
                self.rotary(&to)
            )));
        }
        let mut above = pole;
        above[t] = height;
        let over = if h > 0.0 {
            "moving over the sphere at Q408"
        } else {
            "moving over the sphere at the clearing height"
        };
        self.rapid_xyz(over, above)?;
        self.approach_xyz("approaching the sphere", pole)
    }

    /// Q408 = 0: refuses a turn through `turn` (its angles in order) when `height`, the
    /// tool-axis coordinate that clears the sphere at every angle of it, is outside the
    /// software limits: the probe may not turn lower, and cannot go higher.
    pub(super) fn turn_height_in_limits(
        &self,
        turn: &[Angles],
        height: f64,
    ) -> Result<(), CycleError> {
        let axis = Axis::LINEAR[self.tool.tool_index()];
        let Some(c) = self.ctx.cfg.machine.axis(axis) else {
            return Ok(());
        };
        if (c.min..=c.max).contains(&height) {
            return Ok(());
        }
        let (from, to) = (turn[0], turn[turn.len() - 1]);
        Err(CycleError::Plan(format!(
            "the rotary axes turn from {} to {} only with the probe at {axis}{height:+.4}, where the ball clears the sphere by Q320 + SET_UP at every angle on the way (the sphere rises with them); that is outside the software limits {:+.4} .. {:+.4}; measure a smaller angle range, or put the sphere nearer the rotary axes; nothing moved",
            self.rotary(&from),
            self.rotary(&to),
            c.min,
            c.max
        )))
    }

    /// Q408 > 0: the probe stands there unmonitored while the rotary axes turn, so
    /// it must clear the sphere by the ball radius and SET_UP at every angle on the
    /// way, this turn's (`turn`) and every later one's (the message names one value
    /// for all). Retracts to Q408 above the preset and over the preset in the working
    /// plane; returns the height.
    fn retract_to_q408(&mut self, turn: &[Angles]) -> Result<f64, CycleError> {
        let h = self.plan.params.retract_height;
        let t = self.tool.tool_index();
        let height = self.preset[t] + h;
        let mut path = turn.to_vec();
        path.extend(self.cycle_path());
        let rs = self.plan.params.sphere_radius + self.probe.radius;
        let lowest = crate::cycle451::plan::round_up(
            self.clear_height(&path, rs + self.probe.set_up) - self.preset[t],
        );
        if h < lowest {
            return Err(CycleError::Plan(format!(
                "Q408={h}: the retraction height does not clear the sphere by the ball radius + SET_UP at every angle the rotary axes turn through (the sphere rises with them); the lowest Q408 that clears it is {lowest:.4}{}",
                // The cycle turns from where the axes stood and back there: a table
                // left tilted by a stopped run is the likelier cause than Q408.
                super::locate::turned_table(&self.start)
            )));
        }
        let [main, minor, _] = self.tool.indices();
        // Q408 clears the sphere; from above it, still nearer along the tool axis.
        let here = self.here()?;
        let feed = if height < here[t] {
            self.plan.approach_feed
        } else {
            self.plan.rapid_feed
        };
        let up = AxisPositions::new().with(Axis::LINEAR[t], height);
        self.mv("retracting to Q408", up, feed)?;
        let over = AxisPositions::new()
            .with(Axis::LINEAR[main], self.preset[main])
            .with(Axis::LINEAR[minor], self.preset[minor]);
        self.mv("moving over the preset at Q408", over, self.plan.rapid_feed)?;
        Ok(height)
    }
}
