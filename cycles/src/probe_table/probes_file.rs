//! `probes.toml`: the calibration rows of the touch-probe table, one per probe name,
//! beside the machine configuration as `<machine>.probes.toml`. Cycle 460 writes its
//! row with the same safe write as the kinematics and the preset table (complete or not
//! at all, the previous file kept as `.prev`); a probe without a row is the nominal one
//! of `[[probe]]` (its radius, no offset, no length correction).
//!
//! ```toml
//! [[probe]]
//! name = "TOUCH_PROBE"
//! R = 2.99612        # effective ball radius, mm
//! CAL_OF1 = 0.003    # ball centre off the spindle axis, main / minor axis, mm
//! CAL_OF2 = -0.0004
//! CAL_ANG = 0.0      # spindle angle at calibration, deg
//! L = 0.0021         # length correction, mm (ball centre further from the spindle)
//! calibrated = "2026-11-25 16:20:31 UTC, cycle 460 on a sphere of radius 12.5 mm"
//! [probe.3d]         # optional: 3D calibration
//! elevations = [-60.0, -45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0, 60.0, 75.0]   # an older table starts at 0.0
//! pole = 0.0
//! deviations = [[0.0004, -0.0002, ...], ...]   # mm, per ring, k·360°/n
//! ```

use super::calibration::{Calibration, Table3d};
use super::ProbeEntry;
use hal::atomic_write::{write_atomic_keeping_previous, WriteError};
use hal::config::{ConfigError, MachineConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One row as the file holds it.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationRow {
    /// The probe's name in `[[probe]]` (`TOOL CALL "NAME"`).
    pub name: String,
    #[serde(rename = "R")]
    pub r: f64,
    #[serde(rename = "CAL_OF1")]
    pub cal_of1: f64,
    #[serde(rename = "CAL_OF2")]
    pub cal_of2: f64,
    #[serde(rename = "CAL_ANG")]
    pub cal_ang: f64,
    #[serde(rename = "L")]
    pub l: f64,
    /// When and on what it was calibrated, for the operator.
    #[serde(default)]
    pub calibrated: String,
    #[serde(default, rename = "3d", skip_serializing_if = "Option::is_none")]
    pub table_3d: Option<Table3d>,
}

impl CalibrationRow {
    pub fn new(name: &str, c: &Calibration, calibrated: String) -> Self {
        Self {
            name: name.to_string(),
            r: c.r,
            cal_of1: c.offset[0],
            cal_of2: c.offset[1],
            cal_ang: c.cal_ang,
            l: c.l,
            calibrated,
            table_3d: c.table_3d.clone(),
        }
    }

    pub fn calibration(&self) -> Calibration {
        Calibration {
            r: self.r,
            offset: [self.cal_of1, self.cal_of2],
            cal_ang: self.cal_ang,
            l: self.l,
            table_3d: self.table_3d.clone(),
        }
    }
}

#[derive(Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default, rename = "probe")]
    probes: Vec<CalibrationRow>,
}

/// The calibration rows of a machine's probes.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeCalibrations {
    /// Where it is read from and written to.
    pub path: PathBuf,
    pub rows: Vec<CalibrationRow>,
}

impl ProbeCalibrations {
    /// `<machine>.probes.toml` beside the machine file.
    pub fn default_path(cfg: &MachineConfig) -> PathBuf {
        let dir = cfg.path.parent().unwrap_or(Path::new("."));
        dir.join(format!("{}.probes.toml", cfg.name))
    }

    /// Reads the file at `path`; none there: no rows. Every row must name a probe of
    /// `probes` once, with every value in range.
    pub fn load(path: &Path, probes: &[ProbeEntry]) -> Result<Self, ConfigError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Self {
                    path: path.to_path_buf(),
                    rows: Vec::new(),
                })
            }
            Err(source) => {
                return Err(ConfigError::Read {
                    path: path.to_path_buf(),
                    source,
                })
            }
        };
        Self::parse(&text, path, probes)
    }

    /// Parses and validates `text`; `path` names it in errors.
    pub fn parse(text: &str, path: &Path, probes: &[ProbeEntry]) -> Result<Self, ConfigError> {
        let file: File = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let invalid = |key: String, message: String| ConfigError::Invalid {
            path: path.to_path_buf(),
            key,
            message,
        };
        for (i, row) in file.probes.iter().enumerate() {
            let key = |f: &str| format!("probe[{i}] ({}).{f}", row.name);
            if !probes.iter().any(|p| p.name == row.name) {
                let known: Vec<&str> = probes.iter().map(|p| p.name.as_str()).collect();
                return Err(invalid(
                    key("name"),
                    format!(
                        "no probe \"{}\" in the machine's [[probe]] table (known: {})",
                        row.name,
                        known.join(", ")
                    ),
                ));
            }
            if file.probes[..i].iter().any(|r| r.name == row.name) {
                return Err(invalid(
                    key("name"),
                    "a second row for this probe; one row per probe".into(),
                ));
            }
            if let Some((f, why)) = row.calibration().invalid_field() {
                return Err(invalid(key(f), why));
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            rows: file.probes,
        })
    }

    /// The calibration of `probe`: its row, else the nominal probe of the table.
    pub fn calibration(&self, probe: &ProbeEntry) -> Calibration {
        self.row(&probe.name).map_or_else(
            || Calibration::nominal(probe.radius),
            CalibrationRow::calibration,
        )
    }

    pub fn row(&self, name: &str) -> Option<&CalibrationRow> {
        self.rows.iter().find(|r| r.name == name)
    }

    /// Sets the row of `row.name` (replacing the old one) and writes the file: the
    /// other rows as the file holds them now (read again, so that a row written by
    /// another program meanwhile is kept), complete or not at all.
    pub fn write_row(
        &mut self,
        row: CalibrationRow,
        probes: &[ProbeEntry],
    ) -> Result<(), WriteError> {
        let mut rows =
            Self::load(&self.path, probes).map_or_else(|_| self.rows.clone(), |f| f.rows);
        match rows.iter_mut().find(|r| r.name == row.name) {
            Some(r) => *r = row.clone(),
            None => rows.push(row.clone()),
        }
        let text = format!(
            "# Touch-probe calibration (tchprobe.tp: R, CAL_OF1, CAL_OF2, CAL_ANG; L), written by\n# cycle 460 CALIBRATION OF TS ON A SPHERE. Lengths in mm, angles in degrees.\n\n{}",
            toml::to_string(&File { probes: rows.clone() }).expect("rows serialise")
        );
        write_atomic_keeping_previous(&self.path, text.as_bytes())?;
        self.rows = rows;
        Ok(())
    }
}
