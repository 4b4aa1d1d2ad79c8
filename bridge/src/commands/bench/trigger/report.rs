//! The report: settings, figures and losses printed, and all of it as JSON.

use super::measure::{Latencies, Measured};
use super::stats::Figures;
use super::BenchArgs;
use crate::bench::Summary;
use hal::master::StartupReport;
use serde_json::json;

/// Everything the report prints and writes.
pub(super) struct Report<'a> {
    pub(super) args: &'a BenchArgs,
    pub(super) warmup: u64,
    pub(super) notes: Vec<String>,
    pub(super) startup: StartupReport,
    pub(super) sim_fifo: bool,
    pub(super) drive_priority: i32,
    pub(super) forwarder_priority: i32,
    pub(super) forwarder_fifo: bool,
    pub(super) estimator_fifo: bool,
    pub(super) main_fifo: bool,
    pub(super) measured: Measured,
    pub(super) latencies: Latencies,
}

impl Report<'_> {
    pub(super) fn print_and_write(&self) -> Result<(), String> {
        let l = &self.latencies;
        let (Some(trig), Some(fl)) = (Summary::of(&l.trigger), Summary::of(&l.floor)) else {
            return Err("no trigger or floor sample reached the estimator".into());
        };
        let mut cycles_sorted = self.measured.stop_cycles.clone();
        cycles_sorted.sort_unstable();
        let f = Figures {
            trig,
            fl,
            bus_hop: Summary::of(&l.to_rt),
            ipc_hop: Summary::of(&l.rt_to_estimator),
            wake: self
                .measured
                .wakeup
                .as_ref()
                .ok()
                .and_then(|w| Summary::of(&w.latencies_ns)),
            stop: Summary::of(&self.measured.stop_ns),
            cycles_sorted,
            bus_name: self
                .args
                .can
                .clone()
                .unwrap_or_else(|| "in-process".to_string()),
            wire_modelled: self.args.can.is_none(),
            cpuidle: hal::rt::cpuidle_driver(),
        };
        self.print_settings(&f);
        self.print_figures(&f);
        if let Some(path) = &self.args.json {
            crate::output::write_json(path, &self.json(&f))?;
        }
        Ok(())
    }

    /// What ran, and which real-time settings it got.
    pub(super) fn print_settings(&self, f: &Figures) {
        let args = self.args;
        let startup = &self.startup;
        let sink_name = if args.direct {
            "ContactPublisher in the real-time thread (--direct)"
        } else {
            "ForwardingSink (forwarder thread publishes)"
        };
        say!(
            "probebridge bench trigger: {} triggers ({} warm-up not counted) in {:.1} s; SYNC {} us; {} bus; sink: {}",
            args.triggers,
            self.warmup,
            self.measured.elapsed.as_secs_f64(),
            args.period(),
            f.bus_name,
            sink_name
        );
        let granted = |b: bool| if b { "granted" } else { "NOT granted" };
        say!(
            "SCHED_FIFO: real-time loop {} (priority {}), simulated drives {} ({}), {}, {}; memory {}; CPU wake-up latency {} (cpuidle driver: {}); {} CPUs",
            granted(startup.realtime_priority),
            args.rt_priority,
            granted(self.sim_fifo),
            self.drive_priority,
            if args.direct {
                "no forwarder (--direct)".to_string()
            } else {
                format!("forwarder {} ({})", granted(self.forwarder_fifo), self.forwarder_priority)
            },
            if args.estimator_priority > 0 {
                format!(
                    "estimator {} ({})",
                    granted(self.estimator_fifo),
                    args.estimator_priority
                )
            } else {
                "estimator: ordinary process".to_string()
            },
            if startup.memory_locked { "locked" } else { "NOT locked" },
            if startup.cpu_latency_held {
                "held at 0 us"
            } else {
                "NOT held"
            },
            f.cpuidle.as_deref().unwrap_or("not reported"),
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
        match &self.measured.wakeup {
            Ok(w) => say!(
                "host wake-up floor: {} eventfd pings between two processes, {}, {}",
                w.latencies_ns.len(),
                if w.cross_cpu {
                    "pinned to different CPUs"
                } else {
                    "NOT pinned to different CPUs"
                },
                if w.fifo {
                    format!("SCHED_FIFO {}", args.estimator_priority)
                } else {
                    "ordinary scheduling".to_string()
                }
            ),
            Err(e) => say!("host wake-up floor: not measured: {e}"),
        }
        for n in &self.notes {
            say!("note: {n}");
        }
    }

    /// The latency table, the comparisons with both floors, the targets, anything
    /// lost.
    pub(super) fn print_figures(&self, f: &Figures) {
        say!();
        for line in f.lines() {
            say!("{line}");
        }
        let (l, m) = (&self.latencies, &self.measured);
        let stats = &m.loop_stats;
        let anomalies = l.lost_triggers + l.lost_floor + m.missing_t0 + stats.publish_failures;
        if anomalies > 0 || stats.late_cycles > 0 || stats.skipped_cycles > 0 {
            say!(
                "lost: {} trigger and {} floor samples; {} triggers without t0; {} publish failures; {} late cycles, {} SYNC slots skipped after stalls",
                l.lost_triggers, l.lost_floor, m.missing_t0, stats.publish_failures, stats.late_cycles, stats.skipped_cycles
            );
        }
    }

    /// All figures as JSON (`--json`).
    pub(super) fn json(&self, f: &Figures) -> serde_json::Value {
        let (args, startup, l, m) = (self.args, &self.startup, &self.latencies, &self.measured);
        let mut doc = json!({
            "benchmark": "trigger",
            "triggers": args.triggers,
            "warmup": self.warmup,
            "period_us": args.period(),
            "bus": f.bus_name,
            "bus_load": self.startup.bus_load.percent,
            "bus_load_latch_cycle": self.startup.bus_load.burst_percent,
            "sink": if args.direct { "direct" } else { "forwarding" },
            "elapsed_s": m.elapsed.as_secs_f64(),
            "cpus": std::thread::available_parallelism().map_or(0, |n| n.get()),
            "realtime": {
                "sched_fifo": startup.realtime_priority,
                "priority": args.rt_priority,
                "simulated_drives_sched_fifo": self.sim_fifo,
                "forwarder_sched_fifo": self.forwarder_fifo,
                "estimator_priority": args.estimator_priority,
                "estimator_sched_fifo": self.estimator_fifo,
                "simulated_drives_priority": self.drive_priority,
                "floor_sender_sched_fifo": self.main_fifo,
                "memory_locked": startup.memory_locked,
                "cpu_latency_held": startup.cpu_latency_held,
                "cpuidle_driver": f.cpuidle,
                "host_wakeup_cross_cpu": m.wakeup.as_ref().is_ok_and(|w| w.cross_cpu),
                "host_wakeup_sched_fifo": m.wakeup.as_ref().is_ok_and(|w| w.fifo),
                "notes": self.notes,
            },
            "lost": {
                "trigger_samples": l.lost_triggers,
                "floor_samples": l.lost_floor,
                "triggers_without_t0": m.missing_t0,
                "publish_failures": m.loop_stats.publish_failures,
            },
            "late_cycles": m.loop_stats.late_cycles,
            "skipped_cycles": m.loop_stats.skipped_cycles,
        });
        if let (Some(doc), serde_json::Value::Object(figures)) = (doc.as_object_mut(), f.json()) {
            doc.extend(figures);
        }
        doc
    }
}
