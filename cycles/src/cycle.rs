//! What every measuring cycle has in common: what it runs with besides the machine
//! ([`CycleContext`]) and the one signature all of them have ([`MeasuringCycle`]).

use crate::confirmation::Confirmation;
use crate::cycle_block::CycleBlock;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::error::CycleError;
use crate::kinematics::Estimator;
use crate::machine_time::{TimeLedger, TimeSplit};
use crate::measuring_log::probing3d::Probing3dRecord;
use crate::progress::{ProgressEvent, ProgressSink};
use crate::results::CycleOutput;
use hal::Machine;
use std::path::{Path, PathBuf};

/// What a cycle needs besides the machine; one per program run.
pub struct CycleContext<'a> {
    pub cfg: &'a CyclesConfig,
    /// The machine's active kinematics file (cycles 450, 451).
    pub kinematics: PathBuf,
    /// Where cycle 451 fits its spheres and solves its identification.
    pub estimator: &'a mut dyn Estimator,
    /// Asks a question and returns whether to go on (Q281=2, a large 451 correction,
    /// rotary axes an M function positions).
    pub confirm: &'a mut dyn FnMut(&Confirmation) -> bool,
    pub progress: &'a mut ProgressSink<'a>,
    /// Where measuring logs are written.
    pub out_dir: &'a Path,
    /// The program file, named in the measuring logs.
    pub program: Option<&'a Path>,
    /// Every cycle 444 point of this run so far: TCHPR444.html lists them all.
    pub probing3d: Vec<Probing3dRecord>,
    /// The preset table as the program changed it, and the datum shift.
    pub datum: Datum,
    /// The machine time of the cycle running now, as booked so far (`None` where
    /// nothing times it: a plan).
    pub machine_time: Option<TimeLedger>,
}

impl CycleContext<'_> {
    /// The cycle's machine time up to `now_ns` on the machine's clock.
    pub fn machine_time_at(&self, now_ns: u64) -> Option<TimeSplit> {
        self.machine_time.as_ref().map(|l| l.split_at(now_ns))
    }

    pub fn note(&mut self, block: u32, text: impl Into<String>) {
        (self.progress)(ProgressEvent::Note {
            block,
            text: text.into(),
        });
    }
}

/// A measuring cycle, by its typed parameters: every cycle runs with this signature.
pub trait MeasuringCycle {
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError>;
}
