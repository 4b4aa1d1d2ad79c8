//! A failure that says the probe was not where the program assumed, and the note that
//! says where the program's coordinates pointed (the active preset row).

use crate::datum::Datum;
use crate::error::CycleErrorKind;
use crate::linear::{Coordinates, LinearMove};

/// A failure that says the probe was not where the program assumed: no contact where
/// one was due, or one where none was.
pub(super) fn misplaced(kind: CycleErrorKind) -> bool {
    use hal::ErrorKind as K;
    matches!(
        kind,
        CycleErrorKind::Machine(K::NotTriggered | K::AlreadyDeflected | K::ProbeCollision)
    )
}

/// [`datum_note`] for an `L` move in program coordinates that failed because the probe
/// was not where the program assumed; empty otherwise.
pub(super) fn misplaced_note(kind: hal::ErrorKind, mv: &LinearMove, datum: &Datum) -> String {
    if misplaced(CycleErrorKind::Machine(kind)) && mv.coordinates == Coordinates::Datum {
        datum_note(datum)
    } else {
        String::new()
    }
}

/// "; the active preset is row N (X.. Y.. Z..)": where the program's coordinates
/// pointed, for a failure that may come from a preset set elsewhere.
pub(super) fn datum_note(datum: &Datum) -> String {
    let row = datum.presets.active_row();
    let shift = if datum.shift == [0.0; 3] {
        String::new()
    } else {
        format!(
            ", plus the datum shift X{:+.4} Y{:+.4} Z{:+.4}",
            datum.shift[0], datum.shift[1], datum.shift[2]
        )
    };
    format!(
        " (the program's coordinates were relative to preset row {} of {}: X{:+.4} Y{:+.4} Z{:+.4}{shift}; M91 blocks are machine coordinates)",
        row.number,
        datum.presets.path.display(),
        row.x,
        row.y,
        row.z
    )
}
