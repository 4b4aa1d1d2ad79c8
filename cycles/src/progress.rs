//! What the cycles report while they work, for a console or a UI: the events and the
//! sink they go to. A leaf: the runner and every cycle report through it.

use crate::results::Status;
use hal::AxisPositions;
use std::path::PathBuf;

/// Where progress events go (a closure of the caller).
pub type ProgressSink<'a> = dyn FnMut(ProgressEvent) + 'a;

#[derive(Clone, Debug, PartialEq)]
pub enum ProgressEvent {
    CycleStarted {
        block: u32,
        cycle: u16,
        line: usize,
    },
    Move {
        block: u32,
        target: AxisPositions,
        feed: f64,
    },
    Probe {
        block: u32,
        direction: [f64; 3],
        max_distance: f64,
    },
    /// Latched stylus ball centre, machine XYZ.
    Contact {
        block: u32,
        centre: [f64; 3],
    },
    Note {
        block: u32,
        text: String,
    },
    /// A measuring log (TCHPR431.TXT, TCHPR444.html, TCHPRAUTO.html) was written.
    MeasuringLog {
        block: u32,
        path: PathBuf,
    },
    CycleFinished {
        block: u32,
        cycle: u16,
        status: Status,
    },
}
