//! The figures of a run: the latency summaries, how far the path is from the floors
//! of its own regime, the targets and by how much one is missed.

use crate::bench::{self, Summary};
use serde_json::json;

/// Armed receive: the software path's targets, µs.
pub(super) const ARMED_P50_US: f64 = 15.0;
pub(super) const ARMED_P99_US: f64 = 50.0;
/// Unarmed receive: the software path against the cold eventfd floor, as ratios.
pub(super) const UNARMED_P50_RATIO: f64 = 1.5;
pub(super) const UNARMED_P99_RATIO: f64 = 2.0;

/// The figures of the report.
pub(super) struct Figures {
    /// Whether the estimator polled during the probing moves.
    pub(super) armed: bool,
    /// End to end: latch (t0) to the estimator having the sample (t1).
    pub(super) trig: Summary,
    /// The bare iceoryx2 hop, interleaved with the triggers (cold, same regime).
    pub(super) fl: Summary,
    /// The same hop back to back (hot).
    pub(super) fl_hot: Option<Summary>,
    /// Latch to the last bit of the frame that completed the contact (the modelled
    /// wire time on the in-process bus; the real bus on `--can`).
    pub(super) bus_hop: Option<Summary>,
    /// The software path: that last bit to the estimator.
    pub(super) ipc_hop: Option<Summary>,
    /// Its first stage: the last bit to the publisher's send (the real-time thread's
    /// wake-up, the loop's work on the frame, the write into the preloaned sample).
    pub(super) loop_stage: Option<Summary>,
    /// Its second stage: the send to the estimator having the sample (iceoryx2's send
    /// and notify, the estimator's wake-up or poll, its read).
    pub(super) hop_stage: Option<Summary>,
    /// The host's wake-up (eventfd between two processes), interleaved (cold).
    pub(super) wake: Option<Summary>,
    /// How late a timed wait at the loop's priority runs, interleaved: the floor of
    /// `loop_stage` (the real-time thread waits for each frame's last bit so).
    pub(super) timer: Option<Summary>,
    /// The same back to back (hot).
    pub(super) wake_hot: Option<Summary>,
    pub(super) stop: Option<Summary>,
    pub(super) cycles_sorted: Vec<u64>,
    /// Samples lost: triggers and floors that never reached their estimator.
    pub(super) lost: u64,
    pub(super) bus_name: String,
    pub(super) wire_modelled: bool,
    pub(super) cpuidle: Option<String>,
}

/// `a` against a floor `b`: ratio and difference, at p50 and p99.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Against {
    p50_ratio: f64,
    p99_ratio: f64,
    p50_above_us: f64,
    p99_above_us: f64,
}

impl Against {
    fn of(a: &Summary, floor: &Summary) -> Self {
        Self {
            p50_ratio: a.p50_us / floor.p50_us,
            p99_ratio: a.p99_us / floor.p99_us,
            p50_above_us: a.p50_us - floor.p50_us,
            p99_above_us: a.p99_us - floor.p99_us,
        }
    }

    fn text(&self) -> String {
        format!(
            "p50 {:.2}x (+{:.1} us), p99 {:.2}x (+{:.1} us)",
            self.p50_ratio, self.p50_above_us, self.p99_ratio, self.p99_above_us
        )
    }

    fn to_json(self) -> serde_json::Value {
        json!({
            "p50_ratio": self.p50_ratio,
            "p99_ratio": self.p99_ratio,
            "p50_above_us": self.p50_above_us,
            "p99_above_us": self.p99_above_us,
        })
    }
}

/// One target: what it says, the value, the limit (both in the target's unit).
pub(super) struct Target {
    pub(super) key: &'static str,
    pub(super) what: String,
    pub(super) value: f64,
    pub(super) limit: f64,
    pub(super) unit: &'static str,
}

impl Target {
    pub(super) fn met(&self) -> bool {
        self.value <= self.limit
    }

    fn text(&self) -> String {
        if self.met() {
            format!("{}: met ({:.2} {u})", self.what, self.value, u = self.unit)
        } else {
            format!(
                "{}: MISSED by {:.2} {u} ({:.2} {u}, {:.2}x the limit)",
                self.what,
                self.value - self.limit,
                self.value,
                self.value / self.limit,
                u = self.unit
            )
        }
    }
}

impl Figures {
    /// The software path: the last-bit-to-estimator hop when measured, else the whole
    /// path (no receive time).
    fn software(&self) -> &Summary {
        self.ipc_hop.as_ref().unwrap_or(&self.trig)
    }

    /// Stop latency in cycles at percentile `p`.
    fn stop_cycles(&self, p: f64) -> u64 {
        bench::percentile(&self.cycles_sorted, p)
    }

    /// The targets of this mode (issue 21): armed, absolute; unarmed, against the cold
    /// eventfd floor; both, the stop in the latch cycle and nothing lost.
    pub(super) fn targets(&self) -> Vec<Target> {
        let sw = self.software();
        let mut out = Vec::new();
        let t = |key, what: &str, value, limit, unit| Target {
            key,
            what: what.to_string(),
            value,
            limit,
            unit,
        };
        if self.armed {
            out.push(t(
                "armed_p50",
                "armed: software path p50 <= 15 us",
                sw.p50_us,
                ARMED_P50_US,
                "us",
            ));
            out.push(t(
                "armed_p99",
                "armed: software path p99 <= 50 us",
                sw.p99_us,
                ARMED_P99_US,
                "us",
            ));
        } else if let Some(w) = &self.wake {
            let a = Against::of(sw, w);
            out.push(t(
                "unarmed_p50",
                "unarmed: software path p50 <= 1.5x the cold eventfd floor",
                a.p50_ratio,
                UNARMED_P50_RATIO,
                "x",
            ));
            out.push(t(
                "unarmed_p99",
                "unarmed: software path p99 <= 2x the cold eventfd floor",
                a.p99_ratio,
                UNARMED_P99_RATIO,
                "x",
            ));
        }
        out.push(t(
            "stop_p99_cycles",
            "stop p99 <= 1 cycle",
            self.stop_cycles(99.0) as f64,
            1.0,
            "cycle(s)",
        ));
        out.push(t(
            "lost",
            "no sample lost",
            self.lost as f64,
            0.0,
            "sample(s)",
        ));
        out
    }

    /// The latency table and how far the path is from the floors, as printed.
    pub(super) fn lines(&self) -> Vec<String> {
        let row = |name: &str, s: &Summary| format!("{name:<56}{}", s.row());
        let mut out = vec![format!("{:<56}{}", "", Summary::HEADER)];
        out.push(row("end to end: latch -> estimator (t0 to t1)", &self.trig));
        if let Some(s) = &self.bus_hop {
            let name = if self.wire_modelled {
                "  wire: latch -> last bit of the frame (modelled)"
            } else {
                "  bus: latch -> real-time loop has the frame"
            };
            out.push(row(name, s));
        }
        if let Some(s) = &self.ipc_hop {
            out.push(row("  software path: frame in -> estimator", s));
        }
        if let Some(s) = &self.loop_stage {
            out.push(row(
                "    of which: frame in -> published (real-time loop)",
                s,
            ));
        }
        if let Some(s) = &self.hop_stage {
            out.push(row("    of which: published -> estimator (iceoryx2)", s));
        }
        out.push(row(
            "floor: iceoryx2 hop, cold (between triggers)",
            &self.fl,
        ));
        match &self.wake {
            Some(w) => out.push(row("floor: eventfd wake-up, cold (between triggers)", w)),
            None => out.push("floor: eventfd wake-up, cold: not measured".into()),
        }
        if let Some(t) = &self.timer {
            out.push(row("floor: timer wake-up, late by (loop's priority)", t));
        }
        if let Some(s) = &self.fl_hot {
            out.push(row("hot: iceoryx2 hop, back to back (50 us apart)", s));
        }
        if let Some(s) = &self.wake_hot {
            out.push(row("hot: eventfd wake-up, back to back", s));
        }
        if let Some(s) = &self.stop {
            out.push(row("stop: first latch frame in -> stop sent", s));
        }
        out.push(String::new());
        let sw = self.software();
        out.push(format!(
            "software path vs the cold iceoryx2 hop: {}",
            Against::of(sw, &self.fl).text()
        ));
        if let Some(w) = &self.wake {
            out.push(format!(
                "software path vs the cold eventfd wake-up: {}",
                Against::of(sw, w).text()
            ));
        }
        if let (Some(l), Some(t)) = (&self.loop_stage, &self.timer) {
            out.push(format!(
                "real-time loop stage vs the timer wake-up: {}",
                Against::of(l, t).text()
            ));
        }
        out.push(format!(
            "end to end vs the cold iceoryx2 hop: {}",
            Against::of(&self.trig, &self.fl).text()
        ));
        out.push(format!(
            "stop latency: p50 {} cycle(s), p99 {} (max {}), counted from the cycle the first latch frame arrived in",
            self.stop_cycles(50.0),
            self.stop_cycles(99.0),
            self.cycles_sorted.last().copied().unwrap_or(0),
        ));
        for t in self.targets() {
            out.push(format!("target {}", t.text()));
        }
        out
    }

    /// The figures as JSON (part of `--json`).
    pub(super) fn json(&self) -> serde_json::Value {
        let sw = self.software();
        let targets: serde_json::Map<String, serde_json::Value> = self
            .targets()
            .iter()
            .map(|t| {
                let v = json!({"met": t.met(), "value": t.value, "limit": t.limit, "unit": t.unit});
                (t.key.to_string(), v)
            })
            .collect();
        json!({
            "armed": self.armed,
            "end_to_end_us": self.trig.to_json(),
            "latch_to_rt_us": self.bus_hop.map(Summary::to_json),
            "wire_time_modelled": self.wire_modelled,
            "software_path_us": self.ipc_hop.map(Summary::to_json),
            "software_path_stages_us": {
                "frame_in_to_published": self.loop_stage.map(Summary::to_json),
                "published_to_estimator": self.hop_stage.map(Summary::to_json),
                "loop_stage_vs_timer": self.loop_stage.zip(self.timer).map(|(l, t)| Against::of(&l, &t).to_json()),
            },
            "floor_us": self.fl.to_json(),
            "host_wakeup_us": self.wake.map(Summary::to_json),
            "host_timer_late_us": self.timer.map(Summary::to_json),
            "floor_hot_us": self.fl_hot.map(Summary::to_json),
            "host_wakeup_hot_us": self.wake_hot.map(Summary::to_json),
            "regimes": "floor_us and host_wakeup_us: cold, one per trigger between the triggers (same idle gap); *_hot_us: back to back",
            "software_vs_floor": Against::of(sw, &self.fl).to_json(),
            "end_to_end_vs_floor": Against::of(&self.trig, &self.fl).to_json(),
            "software_vs_host_wakeup": self.wake.map(|w| Against::of(sw, &w).to_json()),
            "end_to_end_vs_host_wakeup": self.wake.map(|w| Against::of(&self.trig, &w).to_json()),
            "software_vs_host_wakeup_hot": self.wake_hot.map(|w| Against::of(sw, &w).to_json()),
            "stop_latency": {
                "us": self.stop.map(Summary::to_json),
                "cycles": {
                    "min": self.cycles_sorted.first(),
                    "p50": self.stop_cycles(50.0),
                    "p99": self.stop_cycles(99.0),
                    "max": self.cycles_sorted.last(),
                },
            },
            "targets": targets,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Synthetic figures: 100 triggers whose software path is 10..=109 us, plus 575 us
    /// of wire time; the cold iceoryx2 floor 5..=104 us; the cold eventfd wake-up
    /// 2..=101 us; the stop in the next cycle every time but once, in the second.
    fn figures() -> Figures {
        let us = |v: u64| v * 1000;
        let sw: Vec<u64> = (10..110).map(us).collect();
        let wire: Vec<u64> = vec![us(575); 100];
        let trig: Vec<u64> = sw.iter().map(|s| s + us(575)).collect();
        let mut cycles = vec![1u64; 100];
        cycles[7] = 2;
        cycles.sort_unstable();
        Figures {
            armed: false,
            trig: Summary::of(&trig).unwrap(),
            fl: Summary::of(&(5..105).map(us).collect::<Vec<_>>()).unwrap(),
            fl_hot: Summary::of(&[us(30); 100]),
            bus_hop: Summary::of(&wire),
            ipc_hop: Summary::of(&sw),
            loop_stage: Summary::of(&(0..100).map(|v| us(4 + v / 10)).collect::<Vec<_>>()),
            hop_stage: Summary::of(&(0..100).map(|v| us(6 + v - v / 10)).collect::<Vec<_>>()),
            wake: Summary::of(&(2..102).map(us).collect::<Vec<_>>()),
            wake_hot: Summary::of(&[us(14); 100]),
            timer: Summary::of(&[us(4); 100]),
            stop: Summary::of(&[us(1900); 100]),
            cycles_sorted: cycles,
            lost: 0,
            bus_name: "in-process".into(),
            wire_modelled: true,
            cpuidle: None,
        }
    }

    fn find(lines: &[String], start: &str) -> String {
        lines
            .iter()
            .find(|l| l.starts_with(start))
            .unwrap_or_else(|| panic!("no line {start:?} in {lines:#?}"))
            .clone()
    }

    #[test]
    fn the_report_gives_the_paths_against_the_cold_floors_the_hot_ones_labelled() {
        let f = figures();
        let lines = f.lines();
        for row in [
            "end to end: latch -> estimator",
            "  wire: latch -> last bit of the frame (modelled)",
            "  software path: frame in -> estimator",
            "    of which: frame in -> published (real-time loop)",
            "    of which: published -> estimator (iceoryx2)",
            "floor: timer wake-up, late by (loop's priority)",
            "real-time loop stage vs the timer wake-up: p50 2.00x (+4.0 us)",
            "floor: iceoryx2 hop, cold (between triggers)",
            "floor: eventfd wake-up, cold (between triggers)",
            "hot: iceoryx2 hop, back to back",
            "hot: eventfd wake-up, back to back",
            "stop: first latch frame in -> stop sent",
        ] {
            find(&lines, row);
        }
        // Software p50 59 us against the cold floors' p50 54 and 51 us; p99 108 against
        // 103 and 100 us.
        assert_eq!(
            find(&lines, "software path vs the cold iceoryx2 hop"),
            "software path vs the cold iceoryx2 hop: p50 1.09x (+5.0 us), p99 1.05x (+5.0 us)"
        );
        assert_eq!(
            find(&lines, "software path vs the cold eventfd wake-up"),
            "software path vs the cold eventfd wake-up: p50 1.16x (+8.0 us), p99 1.08x (+8.0 us)"
        );
        find(
            &lines,
            "end to end vs the cold iceoryx2 hop: p50 11.74x (+580.0 us)",
        );
        assert!(find(&lines, "stop latency:")
            .starts_with("stop latency: p50 1 cycle(s), p99 1 (max 2)"));
        find(
            &lines,
            "target unarmed: software path p50 <= 1.5x the cold eventfd floor: met (1.16 x)",
        );
        find(&lines, "target stop p99 <= 1 cycle: met");

        let j = f.json();
        let stages = &j["software_path_stages_us"];
        assert_eq!(stages["frame_in_to_published"]["p50"], 8.0);
        assert_eq!(stages["published_to_estimator"]["p50"], 51.0);
        assert_eq!(j["stop_latency"]["cycles"]["p99"], 1);
        assert_eq!(j["stop_latency"]["cycles"]["max"], 2);
        assert_eq!(j["targets"]["stop_p99_cycles"]["met"], true);
        assert_eq!(j["software_path_us"]["p50"], 59.0);
        assert_eq!(j["host_wakeup_us"]["p99"], 100.0);
        assert_eq!(j["host_wakeup_hot_us"]["p50"], 14.0);
        assert_eq!(j["end_to_end_us"]["p50"], 634.0);
        // The ratios use the cold floors, not the hot ones.
        assert_eq!(j["software_vs_host_wakeup"]["p50_ratio"], 59.0 / 51.0);
        assert_eq!(j["software_vs_floor"]["p50_ratio"], 59.0 / 54.0);
    }

    #[test]
    fn a_missed_target_says_by_how_much() {
        let mut f = figures();
        f.cycles_sorted = vec![2; 100];
        f.armed = true;
        let lines = f.lines();
        // Armed: p50 59 us against 15.
        find(&lines, "target armed: software path p50 <= 15 us: MISSED by 44.00 us (59.00 us, 3.93x the limit)");
        find(
            &lines,
            "target stop p99 <= 1 cycle: MISSED by 1.00 cycle(s)",
        );
        let j = f.json();
        assert_eq!(j["targets"]["stop_p99_cycles"]["met"], false);
        assert_eq!(j["targets"]["armed_p99"]["value"], 108.0);
        assert!(j["targets"].get("unarmed_p50").is_none());
    }
}
