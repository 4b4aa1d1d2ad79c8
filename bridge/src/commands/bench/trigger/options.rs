//! The options of `probebridge bench trigger`, and the estimator's receive modes it
//! runs.

use crate::estimator::ArmedReceive;
use std::path::PathBuf;

/// The estimator's receive during probing moves, as the bench runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Modes {
    /// Armed, then unarmed.
    Both,
    Armed,
    Unarmed,
}

impl Modes {
    pub(super) fn list(self) -> &'static [ArmedReceive] {
        match self {
            Self::Both => &[ArmedReceive::Auto, ArmedReceive::Off],
            Self::Armed => &[ArmedReceive::Auto],
            Self::Unarmed => &[ArmedReceive::Off],
        }
    }
}

/// The options of `probebridge bench trigger`, parsed by clap straight into this.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchArgs {
    /// Measured triggers (plus a warm-up of 10 %, at most 100).
    #[arg(long, default_value_t = 10_000)]
    pub triggers: u64,
    /// SYNC period of the real-time loop, µs (default: the machine's, 2000). Refused
    /// when the cyclic traffic would load the bus above its limit (70 % of the bit
    /// rate). Modbus: the simulated PLC's task cycle (default 250).
    #[arg(long)]
    pub period_us: Option<u32>,
    /// Run the latch over this SocketCAN interface (simulated drives on a second
    /// socket in this process) instead of the in-process bus.
    #[arg(long)]
    pub can: Option<String>,
    /// Write all figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Which receive of the estimator to measure: armed (`armed_receive = "auto"`),
    /// unarmed (`"off"`), or both, one after the other.
    #[arg(long, value_enum, default_value_t = Modes::Both)]
    pub modes: Modes,
    /// Warm-up triggers, not counted.
    #[arg(long)]
    pub warmup: Option<u64>,
    /// SCHED_FIFO priority of the real-time thread (0: do not ask); the simulated
    /// drives get one less, the floors' sender two less.
    #[arg(long, default_value_t = 80)]
    pub rt_priority: i32,
    /// Run the estimator process under SCHED_FIFO at this priority (0: an
    /// ordinary process, as the bridge starts it). Every thread on the measured
    /// path runs under SCHED_FIFO by default, so other load on the machine does
    /// not decide the result.
    #[arg(long, default_value_t = 70)]
    pub estimator_priority: i32,
    /// SCHED_FIFO priority of the simulated drives' thread (default: the real-time
    /// loop's minus one; 0: ordinary).
    #[arg(long)]
    pub drives_priority: Option<i32>,
    /// Over Modbus TCP on loopback instead: the simulated PLC (its task cycle
    /// --period-us) latches, the bridge polls its status every --poll-ms.
    #[arg(long, conflicts_with = "can")]
    pub modbus: bool,
    /// Modbus: status poll period, ms.
    #[arg(long, default_value_t = 1, requires = "modbus")]
    pub poll_ms: u32,
}

impl BenchArgs {
    /// The SYNC period once resolved (see `run`).
    pub(super) fn period(&self) -> u32 {
        self.period_us.unwrap_or(0)
    }
}
