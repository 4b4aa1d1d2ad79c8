//! A machine as the measuring cycles see it: hal's [`MachineConfig`] and, from the same
//! TOML file, the probe table ([`crate::probe_table`]) and the cycles' machine
//! parameters ([`crate::machine_parameters`]); and beside it the preset table
//! ([`crate::preset_table`]) and the probes' calibration rows
//! ([`crate::probe_table::probes_file`]). hal accepts `[[probe]]` and `[cycles]`
//! unread; they are validated here, just as strictly (unknown keys refused, errors
//! name the file, the key and why).

use crate::machine_parameters::MachineParameters;
use crate::preset_table::PresetTable;
use crate::probe_table::probes_file::ProbeCalibrations;
use crate::probe_table::ProbeEntry;
use hal::config::{ConfigError, MachineConfig};
use serde::Deserialize;
use std::path::Path;

#[derive(Clone, Debug, PartialEq)]
pub struct CyclesConfig {
    pub machine: MachineConfig,
    /// `[[probe]]`, in table order (tool numbers index it from 1).
    pub probes: Vec<ProbeEntry>,
    /// `[cycles]`.
    pub parameters: MachineParameters,
    /// `<machine>.presets.toml` beside the machine file (row 0 at the origin when
    /// there is none); a program starts with its active row.
    pub presets: PresetTable,
    /// `<machine>.probes.toml` beside the machine file: the probes' calibration rows
    /// (none when there is no file), also set on [`Self::probes`].
    pub calibrations: ProbeCalibrations,
}

/// The sections of the machine TOML the cycles own; hal checks every other key.
#[derive(Deserialize)]
struct Sections {
    #[serde(rename = "probe", default)]
    probes: Vec<ProbeEntry>,
    #[serde(default)]
    cycles: MachineParameters,
}

impl CyclesConfig {
    /// Reads and validates the machine TOML at `path`: hal's part and the cycles'.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::of(MachineConfig::load(path)?)
    }

    /// Parses and validates; `path` names the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let machine = MachineConfig::parse(text, path)?;
        Self::with_machine(machine, text)
    }

    /// The cycles' sections for a machine configuration already read (from the file
    /// it was read from, [`MachineConfig::path`]).
    pub fn of(machine: MachineConfig) -> Result<Self, ConfigError> {
        let text =
            hal::config::read_config_text(&machine.path).map_err(|source| ConfigError::Read {
                path: machine.path.clone(),
                source,
            })?;
        Self::with_machine(machine, &text)
    }

    fn with_machine(machine: MachineConfig, text: &str) -> Result<Self, ConfigError> {
        let path = machine.path.clone();
        let s: Sections = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let invalid = |key: String, message: String| ConfigError::Invalid {
            path: path.clone(),
            key,
            message,
        };
        // The motion guard's range: a feed outside it would be refused mid-program.
        let fastest = machine.axes.iter().map(|a| a.max_feed).fold(0.0, f64::max);
        let feeds = hal::config::bounds::MIN_FEED..=fastest;
        for (i, p) in s.probes.iter().enumerate() {
            let key = |f: &str| format!("probe[{i}] ({}).{f}", p.name);
            if let Some((f, why)) = p.invalid_field() {
                return Err(invalid(key(f), why));
            }
            for (f, v) in [("fmax", p.fmax), ("f", p.f)] {
                if !feeds.contains(&v) {
                    return Err(invalid(
                        key(f),
                        format!(
                            "{v} is outside {} .. {fastest} mm/min (the motion guard's minimum feed .. the fastest axis's max_feed)",
                            feeds.start()
                        ),
                    ));
                }
            }
            if let Some(j) = s.probes[..i].iter().position(|q| q.name == p.name) {
                return Err(invalid(
                    key("name"),
                    format!(
                        "\"{}\" is also the name of probe[{j}]; TOOL CALL could not tell them apart",
                        p.name
                    ),
                ));
            }
        }
        if let Some((key, why)) = s.cycles.invalid_field() {
            return Err(invalid(key, why));
        }
        let presets = PresetTable::load(&PresetTable::default_path(&machine), &machine)?;
        let calibrations =
            ProbeCalibrations::load(&ProbeCalibrations::default_path(&machine), &s.probes)?;
        let mut cfg = Self {
            machine,
            probes: s.probes,
            parameters: s.cycles,
            presets,
            calibrations,
        };
        cfg.apply_calibrations();
        Ok(cfg)
    }

    /// Sets each probe's calibration from [`Self::calibrations`] (after the rows or
    /// the radii changed).
    pub fn apply_calibrations(&mut self) {
        for p in &mut self.probes {
            p.calibration = self.calibrations.row(&p.name).map(|r| r.calibration());
        }
    }

    /// Reads the calibration rows from `path` instead (a test's or a run's own copy)
    /// and applies them.
    pub fn use_calibrations(&mut self, path: &std::path::Path) -> Result<(), ConfigError> {
        self.calibrations = ProbeCalibrations::load(path, &self.probes)?;
        self.apply_calibrations();
        Ok(())
    }

    /// The same configuration with the machine's state read again from its files: the
    /// preset table's rows and the probes' calibration rows, as a run (451, 460) may
    /// have rewritten them since. A long-running service starts each program with this,
    /// as a new `probebridge run` would. The active preset row stays the one of this
    /// configuration while the table still has it (a scenario's start row).
    pub fn reread_state(&self) -> Result<Self, ConfigError> {
        let mut cfg = self.clone();
        cfg.presets = PresetTable::load(&self.presets.path, &self.machine)?;
        if cfg.presets.row(self.presets.active).is_some() {
            cfg.presets.active = self.presets.active;
        }
        cfg.calibrations = ProbeCalibrations::load(&self.calibrations.path, &self.probes)?;
        cfg.apply_calibrations();
        Ok(cfg)
    }

    /// Makes row `number` the active preset the program starts with (a scenario's
    /// `preset`); `Err` names the rows there are.
    pub fn start_with_preset(&mut self, number: u32) -> Result<(), String> {
        self.presets.activate(number)
    }

    pub fn probe(&self, name: &str) -> Option<&ProbeEntry> {
        self.probes.iter().find(|p| p.name == name)
    }
}
