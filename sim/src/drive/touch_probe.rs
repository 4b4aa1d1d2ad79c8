//! Touch probe 1 (CiA 402 0x60B8-0x60BA): armed by the touch probe function, it
//! latches the exact position at the instant the probe signal rises within a step.

use super::{Objects, SimDrive};
use hal::cia402::{Probe, TouchProbeFunction, TouchProbeStatus};

impl Objects {
    /// Enabling touch probe 1 (again) clears its stored edges, as a real drive does,
    /// so each probing move latches afresh.
    pub(super) fn apply_touch_probe_function(&mut self) {
        let f = TouchProbeFunction::from_bits(self.app.tp_function);
        let level = self.app.tp_status & TouchProbeStatus::INPUT_LEVEL;
        self.app.tp_status = level
            | if f.enabled(Probe::One) {
                TouchProbeStatus::ENABLED
            } else {
                0
            };
    }
}

impl SimDrive {
    /// Starts a simulation step: remembers where the axis starts from.
    pub fn begin_step(&mut self) {
        self.step_from = self.od.actual;
        self.od.take_set_point();
    }

    /// Ends a step at `to_inc`. `latch_fraction`: the probe signal rose at this
    /// fraction of the step; `level`: the probe signal at the end of the step.
    /// Returns whether touch probe 1 latched in this step.
    pub fn end_step(&mut self, to_inc: i32, latch_fraction: Option<f64>, level: bool) -> bool {
        let mut latched = false;
        let app = &mut self.od.app;
        if let Some(frac) = latch_fraction {
            let f = TouchProbeFunction::from_bits(app.tp_function);
            let st = TouchProbeStatus::from_bits(app.tp_status);
            // First-event mode latches once until re-armed; continuous mode every edge.
            let room = !st.positive_edge_stored(Probe::One) || f.continuous(Probe::One);
            let armed = f.enabled(Probe::One) && f.sample_positive_edge(Probe::One) && room;
            if armed {
                let from = self.step_from as f64;
                let pos = from + frac * (to_inc as f64 - from);
                app.tp_pos_edge = pos.round() as i32;
                app.tp_status |= TouchProbeStatus::POSITIVE_EDGE_STORED;
                latched = true;
            }
        }
        if level {
            app.tp_status |= TouchProbeStatus::INPUT_LEVEL;
        } else {
            app.tp_status &= !TouchProbeStatus::INPUT_LEVEL;
        }
        self.od.actual = to_inc;
        latched
    }
}
