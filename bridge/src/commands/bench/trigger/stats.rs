//! The figures of a run: the latency summaries, how far the path is from the floors,
//! the targets.

use crate::bench::{self, Summary};
use serde_json::json;

/// The figures of the report.
pub(super) struct Figures {
    /// End to end: latch (t0) to the estimator having the sample (t1).
    pub(super) trig: Summary,
    /// The bare iceoryx2 hop, same processes.
    pub(super) fl: Summary,
    /// Latch to the last bit of the frame that completed the contact (the modelled
    /// wire time on the in-process bus; the real bus on `--can`).
    pub(super) bus_hop: Option<Summary>,
    /// The software path: that last bit to the estimator.
    pub(super) ipc_hop: Option<Summary>,
    /// The host's cross-CPU wake-up (eventfd between two processes).
    pub(super) wake: Option<Summary>,
    pub(super) stop: Option<Summary>,
    pub(super) cycles_sorted: Vec<u64>,
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

impl Figures {
    /// The software path: the last-bit-to-estimator hop when measured, else the whole
    /// path (no receive time).
    pub(super) fn software(&self) -> &Summary {
        self.ipc_hop.as_ref().unwrap_or(&self.trig)
    }

    /// Stop latency in cycles at percentile `p`.
    pub(super) fn stop_cycles(&self, p: f64) -> u64 {
        bench::percentile(&self.cycles_sorted, p)
    }

    /// The latency table and how far the path is from both floors, as printed.
    pub(super) fn lines(&self) -> Vec<String> {
        let row = |name: &str, s: &Summary| format!("{name:<52}{}", s.row());
        let mut out = vec![format!("{:<52}{}", "", Summary::HEADER)];
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
        out.push(row("floor: bare iceoryx2 hop, same processes", &self.fl));
        match &self.wake {
            Some(w) => out.push(row("floor: host cross-CPU wake-up (eventfd)", w)),
            None => out.push("floor: host cross-CPU wake-up: not measured".into()),
        }
        if let Some(s) = &self.stop {
            out.push(row("stop: first latch frame in -> stop sent", s));
        }
        out.push(String::new());
        let sw = self.software();
        out.push(format!(
            "software path vs the iceoryx2 floor: {}",
            Against::of(sw, &self.fl).text()
        ));
        out.push(format!(
            "end to end vs the iceoryx2 floor: {}",
            Against::of(&self.trig, &self.fl).text()
        ));
        if let Some(w) = &self.wake {
            out.push(format!(
                "software path vs the host's wake-up: {}",
                Against::of(sw, w).text()
            ));
            out.push(format!(
                "end to end vs the host's wake-up: {}",
                Against::of(&self.trig, w).text()
            ));
        }
        out.push(format!(
            "stop latency: p50 {} cycle(s), p99 {} (max {}), counted from the cycle the first latch frame arrived in; target p99 <= 1: {}",
            self.stop_cycles(50.0),
            self.stop_cycles(99.0),
            self.cycles_sorted.last().copied().unwrap_or(0),
            yes_no(self.stop_cycles(99.0) <= 1)
        ));
        out.push(format!(
            "software path targets: p99 <= 20 us: {}; p99.9 <= 50 us: {}; p50 within 2x the iceoryx2 floor: {}",
            yes_no(sw.p99_us <= 20.0),
            yes_no(sw.p999_us <= 50.0),
            yes_no(Against::of(sw, &self.fl).p50_ratio <= 2.0)
        ));
        out
    }

    /// The figures as JSON (part of `--json`).
    pub(super) fn json(&self) -> serde_json::Value {
        let sw = self.software();
        json!({
            "end_to_end_us": self.trig.to_json(),
            "trigger_latency_us": self.trig.to_json(),
            "latch_to_rt_us": self.bus_hop.map(Summary::to_json),
            "wire_time_modelled": self.wire_modelled,
            "software_path_us": self.ipc_hop.map(Summary::to_json),
            "rt_to_estimator_us": self.ipc_hop.map(Summary::to_json),
            "floor_us": self.fl.to_json(),
            "host_wakeup_us": self.wake.map(Summary::to_json),
            "software_vs_floor": Against::of(sw, &self.fl).to_json(),
            "end_to_end_vs_floor": Against::of(&self.trig, &self.fl).to_json(),
            "software_vs_host_wakeup": self.wake.map(|w| Against::of(sw, &w).to_json()),
            "end_to_end_vs_host_wakeup": self.wake.map(|w| Against::of(&self.trig, &w).to_json()),
            "stop_latency": {
                "us": self.stop.map(Summary::to_json),
                "cycles": {
                    "min": self.cycles_sorted.first(),
                    "p50": self.stop_cycles(50.0),
                    "p99": self.stop_cycles(99.0),
                    "max": self.cycles_sorted.last(),
                },
            },
            "targets": {
                "software_p99_le_20us": sw.p99_us <= 20.0,
                "software_p99_9_le_50us": sw.p999_us <= 50.0,
                "software_p50_within_2x_floor": Against::of(sw, &self.fl).p50_ratio <= 2.0,
                "stop_p99_le_1_cycle": self.stop_cycles(99.0) <= 1,
            },
        })
    }
}

fn yes_no(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "MISSED"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Synthetic figures: 100 triggers whose software path is 10..=109 us, plus 575 us
    /// of wire time; the iceoryx2 floor 5..=104 us; the host's wake-up 2..=101 us;
    /// the stop in the next cycle every time but once, in the second.
    fn figures() -> Figures {
        let us = |v: u64| v * 1000;
        let sw: Vec<u64> = (10..110).map(us).collect();
        let wire: Vec<u64> = vec![us(575); 100];
        let trig: Vec<u64> = sw.iter().map(|s| s + us(575)).collect();
        let mut cycles = vec![1u64; 100];
        cycles[7] = 2;
        cycles.sort_unstable();
        Figures {
            trig: Summary::of(&trig).unwrap(),
            fl: Summary::of(&(5..105).map(us).collect::<Vec<_>>()).unwrap(),
            bus_hop: Summary::of(&wire),
            ipc_hop: Summary::of(&sw),
            wake: Summary::of(&(2..102).map(us).collect::<Vec<_>>()),
            stop: Summary::of(&[us(1900); 100]),
            cycles_sorted: cycles,
            bus_name: "in-process".into(),
            wire_modelled: true,
            cpuidle: None,
        }
    }

    #[test]
    fn the_report_gives_both_paths_against_both_floors_and_the_stop_in_cycles() {
        let f = figures();
        let lines = f.lines();
        let find = |start: &str| {
            lines
                .iter()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("no line {start:?} in {lines:#?}"))
                .clone()
        };
        for row in [
            "end to end: latch -> estimator",
            "  wire: latch -> last bit of the frame (modelled)",
            "  software path: frame in -> estimator",
            "floor: bare iceoryx2 hop",
            "floor: host cross-CPU wake-up (eventfd)",
            "stop: first latch frame in -> stop sent",
        ] {
            find(row);
        }
        // Software p50 59 us against the floors' p50 54 and 51 us; p99 108 against
        // 103 and 100 us.
        assert_eq!(
            find("software path vs the iceoryx2 floor"),
            "software path vs the iceoryx2 floor: p50 1.09x (+5.0 us), p99 1.05x (+5.0 us)"
        );
        assert_eq!(
            find("software path vs the host's wake-up"),
            "software path vs the host's wake-up: p50 1.16x (+8.0 us), p99 1.08x (+8.0 us)"
        );
        find("end to end vs the iceoryx2 floor: p50 11.74x (+580.0 us)");
        find("end to end vs the host's wake-up");
        // 99 of 100 in one cycle: p50 and p99 are 1, the maximum 2.
        assert!(find("stop latency:").starts_with("stop latency: p50 1 cycle(s), p99 1 (max 2)"));
        assert!(find("stop latency:").ends_with("target p99 <= 1: met"));

        let j = f.json();
        assert_eq!(j["stop_latency"]["cycles"]["p99"], 1);
        assert_eq!(j["stop_latency"]["cycles"]["max"], 2);
        assert_eq!(j["targets"]["stop_p99_le_1_cycle"], true);
        assert_eq!(j["software_path_us"]["p50"], 59.0);
        assert_eq!(j["host_wakeup_us"]["p99"], 100.0);
        assert_eq!(j["end_to_end_us"]["p50"], 634.0);
        assert!(j["software_vs_host_wakeup"]["p99_ratio"].is_number());
    }

    #[test]
    fn a_late_stop_misses_the_cycle_target() {
        let mut f = figures();
        f.cycles_sorted = vec![2; 100];
        assert!(f
            .lines()
            .iter()
            .any(|l| l.starts_with("stop latency: p50 2") && l.ends_with("MISSED")));
        assert_eq!(f.json()["targets"]["stop_p99_le_1_cycle"], false);
    }
}
