//! The report: settings, figures and losses printed, and all of it as JSON.

use super::measure::{Latencies, Measured};
use super::options::BenchArgs;
use super::stats::Figures;
use crate::bench::Summary;
use crate::estimator::ArmedReceive;
use hal::master::StartupReport;
use serde_json::json;

/// Everything the report of one mode prints and writes.
pub(super) struct Report {
    pub(super) args: BenchArgs,
    pub(super) mode: ArmedReceive,
    /// What the estimator said of its armed receive (its log).
    pub(super) armed: Option<String>,
    pub(super) warmup: u64,
    pub(super) notes: Vec<String>,
    pub(super) startup: StartupReport,
    pub(super) sim_fifo: bool,
    pub(super) drive_priority: i32,
    pub(super) sender_priority: i32,
    pub(super) estimator_fifo: bool,
    pub(super) main_fifo: bool,
    pub(super) measured: Measured,
    pub(super) latencies: Latencies,
}

impl Report {
    /// Prints the report; returns its JSON.
    pub(super) fn print(&self) -> Result<serde_json::Value, String> {
        let f = self.figures()?;
        self.print_settings(&f);
        self.print_figures(&f);
        Ok(self.json(&f))
    }

    fn figures(&self) -> Result<Figures, String> {
        let (l, m) = (&self.latencies, &self.measured);
        let (Some(trig), Some(fl)) = (Summary::of(&l.trigger), Summary::of(&l.floor)) else {
            return Err("no trigger or floor sample reached its estimator".into());
        };
        let mut cycles_sorted = m.stop_cycles.clone();
        cycles_sorted.sort_unstable();
        Ok(Figures {
            armed: self.armed.as_deref().is_some_and(|a| a.starts_with("on")),
            trig,
            fl,
            fl_hot: Summary::of(&l.floor_hot),
            bus_hop: Summary::of(&l.to_rt),
            ipc_hop: Summary::of(&l.rt_to_estimator),
            loop_stage: Summary::of(&l.rt_to_published),
            hop_stage: Summary::of(&l.published_to_estimator),
            wake: Summary::of(&m.cold_wakeup_ns),
            timer: Summary::of(&m.cold_timer_ns),
            wake_hot: m
                .wakeup
                .as_ref()
                .ok()
                .and_then(|w| Summary::of(&w.latencies_ns)),
            stop: Summary::of(&m.stop_ns),
            cycles_sorted,
            lost: l.lost_triggers + l.lost_floor + m.missing_t0 + m.loop_stats.publish_failures,
            bus_name: self
                .args
                .can
                .clone()
                .unwrap_or_else(|| "in-process".to_string()),
            wire_modelled: self.args.can.is_none(),
            cpuidle: hal::rt::cpuidle_driver(),
        })
    }

    /// What ran, and which real-time settings it got.
    fn print_settings(&self, f: &Figures) {
        let args = &self.args;
        let startup = &self.startup;
        say!();
        say!(
            "probebridge bench trigger, estimator receive \"{}\" ({}): {} triggers ({} warm-up not counted) in {:.1} s; SYNC {} us; {} bus; sink: ContactPublisher in the real-time thread (one hop)",
            self.mode.as_str(),
            self.armed.as_deref().unwrap_or("not reported"),
            args.triggers,
            self.warmup,
            self.measured.elapsed.as_secs_f64(),
            args.period(),
            f.bus_name,
        );
        let granted = |b: bool| if b { "granted" } else { "NOT granted" };
        say!(
            "SCHED_FIFO: real-time loop {} (priority {}, {}), simulated drives {} ({}), floors' sender {} ({}), {}; memory {}; CPU wake-up latency {} (cpuidle driver: {}); {} CPUs; load average {}",
            granted(startup.realtime_priority),
            args.rt_priority,
            startup
                .rt_cpu
                .map_or_else(|| "on any CPU".to_string(), |c| format!("on CPU {c}")),
            granted(self.sim_fifo),
            self.drive_priority,
            granted(self.main_fifo),
            self.sender_priority,
            if args.estimator_priority > 0 {
                format!(
                    "estimators {} ({})",
                    granted(self.estimator_fifo),
                    args.estimator_priority
                )
            } else {
                "estimators: ordinary processes".to_string()
            },
            if startup.memory_locked { "locked" } else { "NOT locked" },
            if startup.cpu_latency_held {
                "held at 0 us"
            } else {
                "NOT held"
            },
            f.cpuidle.as_deref().unwrap_or("not reported"),
            hal::rt::online_cpus().len(),
            load_average()
        );
        if let Some(e) = &self.measured.cold_timer_error {
            say!("timer floor: {e}");
        }
        if let Some(e) = &self.measured.cold_wakeup_error {
            say!("cold eventfd floor: {e}");
        }
        if let Err(e) = &self.measured.wakeup {
            say!("hot eventfd floor: not measured: {e}");
        }
        for n in &self.notes {
            say!("note: {n}");
        }
    }

    /// The latency table, the comparisons with the floors, the targets, anything lost.
    fn print_figures(&self, f: &Figures) {
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

    /// All figures of this mode as JSON.
    fn json(&self, f: &Figures) -> serde_json::Value {
        let (args, startup, l, m) = (&self.args, &self.startup, &self.latencies, &self.measured);
        let mut doc = json!({
            "benchmark": "trigger",
            "armed_receive": self.mode.as_str(),
            "armed_state": self.armed,
            "triggers": args.triggers,
            "warmup": self.warmup,
            "period_us": args.period(),
            "bus": f.bus_name,
            "bus_load": self.startup.bus_load.percent,
            "bus_load_latch_cycle": self.startup.bus_load.burst_percent,
            "sink": "direct",
            "elapsed_s": m.elapsed.as_secs_f64(),
            "cpus": hal::rt::online_cpus().len(),
            "load_average": load_average(),
            "realtime": {
                "sched_fifo": startup.realtime_priority,
                "priority": args.rt_priority,
                "simulated_drives_sched_fifo": self.sim_fifo,
                "estimator_priority": args.estimator_priority,
                "estimator_sched_fifo": self.estimator_fifo,
                "simulated_drives_priority": self.drive_priority,
                "floor_sender_sched_fifo": self.main_fifo,
                "rt_cpu": startup.rt_cpu,
                "memory_locked": startup.memory_locked,
                "cpu_latency_held": startup.cpu_latency_held,
                "cpuidle_driver": f.cpuidle,
                "host_wakeup_hot_cross_cpu": m.wakeup.as_ref().is_ok_and(|w| w.cross_cpu),
                "host_wakeup_hot_sched_fifo": m.wakeup.as_ref().is_ok_and(|w| w.fifo),
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

/// The host's load average (1, 5, 15 min), as /proc/loadavg gives it: the bench
/// shares the machine, and says with what.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "not reported".into())
}
