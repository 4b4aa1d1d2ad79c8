//! ISO 230-7 names of the location errors and the zero error of a rotary axis
//! (`EX0C`: the X position error of the C axis's line, `EC0C`: its zero error).

use hal::Axis;

/// ISO 230-7 names of the errors a rotary axis can carry: location errors in QS order,
/// then the zero error.
pub fn error_names(axis: Axis) -> &'static [&'static str] {
    match axis {
        Axis::A => &["EY0A", "EZ0A", "EB0A", "EC0A", "EA0A"],
        Axis::B => &["EZ0B", "EX0B", "EC0B", "EA0B", "EB0B"],
        Axis::C => &["EX0C", "EY0C", "EA0C", "EB0C", "EC0C"],
        _ => &[],
    }
}
