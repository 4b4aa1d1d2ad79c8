//! The program's unit (`BEGIN PGM NAME MM|INCH`); values inside a program are mm.

/// Unit of the program (`BEGIN PGM NAME MM|INCH`); values inside [`crate::program::Program`]
/// are mm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LengthUnit {
    Mm,
    Inch,
}
