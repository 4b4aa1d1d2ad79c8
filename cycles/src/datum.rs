//! The datum of a running program, as on the TNC: the active row of the preset table
//! plus the datum shift of the program (cycle 7 DATUM SHIFT, TRANS DATUM, ISO G54).
//! `L` blocks and the positions and results of cycles 431 and 444 are in these
//! coordinates: machine = program + preset + shift (X/Y/Z), machine = program + the
//! row's offset (A/B/C).

use crate::preset_table::PresetTable;
use hal::{Axis, AxisPositions};

/// A block that changes the datum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DatumBlock {
    /// `CYCL DEF 247 DATUM SETTING Q339=n` / `G247 Q339=n`: row `n` becomes active.
    Preset(u32),
    /// `TRANS DATUM AXIS X.. Y.. Z..` / `G54 X.. Y.. Z..` / `CYCL DEF 7.0 DATUM SHIFT`
    /// (which starts a shift of 0 that its 7.1.. blocks fill): the whole shift, mm.
    Shift([f64; 3]),
    /// `CYCL DEF 7.1 X+10` ...: one axis (0 X, 1 Y, 2 Z) of the shift, mm.
    ShiftAxis(usize, f64),
    /// `TRANS DATUM RESET`.
    Reset,
}

/// The preset table as the program has changed it, and the shift.
#[derive(Clone, Debug, PartialEq)]
pub struct Datum {
    pub presets: PresetTable,
    /// mm, machine X/Y/Z.
    pub shift: [f64; 3],
}

impl Datum {
    pub fn new(presets: PresetTable) -> Self {
        Datum {
            presets,
            shift: [0.0; 3],
        }
    }

    /// Where the program's X/Y/Z origin is, machine X/Y/Z: preset plus shift.
    pub fn origin(&self) -> [f64; 3] {
        let p = self.presets.active_row().xyz();
        [0, 1, 2].map(|i| p[i] + self.shift[i])
    }

    /// Carries out a datum block; `Err` when the preset row does not exist.
    pub fn apply(&mut self, block: &DatumBlock) -> Result<(), String> {
        match *block {
            DatumBlock::Preset(n) => self.presets.activate(n)?,
            DatumBlock::Shift(s) => self.shift = s,
            DatumBlock::ShiftAxis(i, v) => self.shift[i] = v,
            DatumBlock::Reset => self.shift = [0.0; 3],
        }
        Ok(())
    }

    /// A target in program coordinates to machine coordinates.
    pub fn to_machine(&self, target: &AxisPositions) -> AxisPositions {
        let o = self.origin();
        let row = self.presets.active_row();
        let mut m = AxisPositions::new();
        for axis in Axis::ALL {
            if let Some(v) = target.get(axis) {
                let offset = match axis.index() {
                    i @ 0..=2 => o[i],
                    _ => row.rotary(axis),
                };
                m.set(axis, v + offset);
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preset_table::Preset;
    use std::path::PathBuf;

    #[test]
    fn preset_plus_shift() {
        let mut row = Preset::origin(1);
        [row.x, row.y, row.z] = [50.0, -30.0, 80.0];
        row.c = Some(10.0);
        let table = PresetTable {
            machine: "m".into(),
            active: 0,
            rows: vec![Preset::origin(0), row],
            path: PathBuf::from("m.presets.toml"),
        };
        let mut d = Datum::new(table);
        assert_eq!(d.origin(), [0.0; 3]);
        d.apply(&DatumBlock::Preset(1)).unwrap();
        d.apply(&DatumBlock::Shift([1.0, 2.0, 3.0])).unwrap();
        d.apply(&DatumBlock::ShiftAxis(2, -5.0)).unwrap();
        assert_eq!(d.origin(), [51.0, -28.0, 75.0]);
        let t = AxisPositions::new().with(Axis::X, 1.0).with(Axis::C, 5.0);
        let m = d.to_machine(&t);
        assert_eq!((m.get(Axis::X), m.get(Axis::Y)), (Some(52.0), None));
        assert_eq!(m.get(Axis::C), Some(15.0));
        d.apply(&DatumBlock::Reset).unwrap();
        assert_eq!(d.origin(), [50.0, -30.0, 80.0]);
        let e = d.apply(&DatumBlock::Preset(4)).unwrap_err();
        assert!(e.contains("rows: 0, 1"), "{e}");
    }
}
