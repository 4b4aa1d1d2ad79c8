//! A scenario: one TOML file that adds the truth to a machine configuration, i.e.
//! what the simulated machine really is (location errors, backlash, Hirth grid, the
//! real stylus ball, noise) and what stands on its table (artefacts), plus optional
//! drive faults for the drive simulation.
//!
//! ```toml
//! machine = "table-ac"   # configs/machines/table-ac.toml, or a path to a .toml
//! seed = 1               # noise seed (default 0)
//! home = [0.0, 250.0, 0.0] # optional: where X, Y, Z start (rotary axes at 0); default
//!                        # X 0, Y 0, Z 50 below its max (a vertical spindle's top)
//! [probe]
//! ball_radius = 3.0      # true stylus ball radius, mm
//! noise = 0.0            # mm, 1 sigma, along the probing direction (default 0)
//! pretravel = 0.0        # mm (default 0)
//! table_radius = 3.0     # optional: R the probe table holds; default ball_radius
//! # A real (kinematic) probe; all optional, off by default (see crate::stylus):
//! axis = "Z"             # the spindle's tool axis, X, Y or Z (default Z)
//! pretravel_axial = 0.0  # mm, pushing the ball along the stylus (default pretravel)
//! lobing = 0.0           # mm, amplitude of the seat's three lobes (<= pretravel)
//! lobing_phase = 0.0     # deg, azimuth of the first lobe at spindle 0°
//! offset = [0.0, 0.0]    # mm, ball centre off the spindle axis (main, minor) at 0°
//! length_error = 0.0     # mm, ball centre further from the spindle than the table says
//! [truth]                # ISO 230-7 names, mm and deg; every key optional
//! EX0C = 0.012
//! EC0C = 0.0             # zero-position error of C (also EA0A, EB0B)
//! backlash_C = 0.0       # deg (also _A, _B)
//! hirth_C = 0.0          # deg; 0 = none; absent = the machine's [[axis]] hirth
//! [[sphere]]             # artefacts in table coordinates, all rotary axes at 0
//! center = [0.0, 0.0, 100.0]
//! radius = 12.5
//! [[plane]]              # material on the side opposite the normal
//! point = [0.0, 0.0, 10.0]
//! normal = [0.0, 0.0, 1.0]
//! [[cylinder]]           # solid, infinite, probed from outside
//! point = [60.0, 0.0, 20.0]
//! direction = [0.0, 1.0, 0.0]
//! radius = 15.0
//! [[fault]]              # for the drive simulation
//! node = 5
//! kind = "emcy"          # or "silent"
//! after_ms = 100.0
//! code = 0x8611          # optional, emcy only
//! ```
//!
//! Parsing is strict: unknown keys and out-of-range values are errors that name the
//! file, the key and why.

mod artefacts;
mod error;
mod fault;
mod probe;
mod truth;

pub use error::ScenarioError;
pub use fault::{Fault, FaultKind};
pub use probe::ProbeTruth;
pub(crate) use truth::effective_hirth;
pub use truth::{RotaryTruth, Truth};

use artefacts::{build_artefacts, RawCylinder, RawPlane, RawSphere};
use error::{check_range, invalid};
use fault::{build_faults, RawFault};
use hal::config::{ConfigError, MachineConfig};
use hal::Axis;
use probe::{build_probe, RawProbe};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use truth::build_truth;

use crate::artefact::{Cylinder, Plane, Sphere};

/// A loaded and validated scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    pub machine: MachineConfig,
    pub seed: u64,
    /// `preset`: the number of the preset table row the control starts with (the
    /// cycles check it against the machine's preset table); `None`: the table's own.
    pub preset: Option<u32>,
    /// `home`: where the X, Y, Z drives start, inside the software limits (a machine
    /// whose spindle is horizontal starts with the probe back along its tool axis);
    /// `None`: [`crate::machine::SimMachine::home`].
    pub home: Option<[f64; 3]>,
    pub probe: ProbeTruth,
    pub truth: Truth,
    pub spheres: Vec<Sphere>,
    pub planes: Vec<Plane>,
    pub cylinders: Vec<Cylinder>,
    pub faults: Vec<Fault>,
    /// Where the scenario was read from.
    pub path: PathBuf,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    machine: String,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    preset: Option<u32>,
    #[serde(default)]
    home: Option<[f64; 3]>,
    probe: RawProbe,
    #[serde(default)]
    truth: BTreeMap<String, f64>,
    #[serde(default)]
    sphere: Vec<RawSphere>,
    #[serde(default)]
    plane: Vec<RawPlane>,
    #[serde(default)]
    cylinder: Vec<RawCylinder>,
    #[serde(default)]
    fault: Vec<RawFault>,
}

impl Scenario {
    /// Reads and validates a scenario. A machine given by name is looked up as
    /// `<scenario dir>/../machines/NAME.toml`, then `<machines_dir>/NAME.toml`, then
    /// `<machines_dir>/machines/NAME.toml` (so either the machines folder or the
    /// configs folder may be passed).
    pub fn load(path: &Path, machines_dir: Option<&Path>) -> Result<Self, ScenarioError> {
        let text = hal::config::read_config_text(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path, machines_dir)
    }

    /// Parses and validates `text`; `path` names the source in errors and anchors a
    /// relative machine reference. Loads the machine configuration it names.
    pub fn parse(
        text: &str,
        path: &Path,
        machines_dir: Option<&Path>,
    ) -> Result<Self, ScenarioError> {
        let raw = Self::parse_raw(text, path)?;
        let machine_path = resolve_machine(&raw.machine, path, machines_dir)?;
        let machine =
            MachineConfig::load(&machine_path).map_err(|source| ScenarioError::Machine {
                path: path.to_path_buf(),
                source,
            })?;
        Self::build(raw, path, machine)
    }

    /// As [`Scenario::parse`] with the machine configuration given instead of loaded
    /// (tests, or a bridge that already holds it). The `machine` key must still be
    /// present; when it is a bare name it must equal `machine.name`.
    pub fn parse_with_machine(
        text: &str,
        path: &Path,
        machine: MachineConfig,
    ) -> Result<Self, ScenarioError> {
        let raw = Self::parse_raw(text, path)?;
        if !is_path_like(&raw.machine) && raw.machine != machine.name {
            return Err(invalid(
                path,
                "machine",
                format!(
                    "names \"{}\" but the machine given is \"{}\"",
                    raw.machine, machine.name
                ),
            ));
        }
        Self::build(raw, path, machine)
    }

    /// R for the probe table: `table_radius`, else the true ball radius.
    pub fn probe_table_radius(&self) -> f64 {
        self.probe.table_radius.unwrap_or(self.probe.ball_radius)
    }

    /// Effective Hirth grid of a rotary axis, deg (0 = none): the scenario's
    /// `hirth_*` when given, else the machine configuration's.
    pub fn hirth(&self, axis: Axis) -> f64 {
        effective_hirth(&self.machine, &self.truth, axis)
    }

    fn parse_raw(text: &str, path: &Path) -> Result<RawScenario, ScenarioError> {
        toml::from_str(text).map_err(|e| {
            ConfigError::Parse {
                path: path.to_path_buf(),
                message: e.to_string().trim_end().to_string(),
            }
            .into()
        })
    }

    fn build(raw: RawScenario, path: &Path, machine: MachineConfig) -> Result<Self, ScenarioError> {
        let probe = build_probe(&raw.probe, path)?;
        let truth = build_truth(&raw.truth, path, &machine)?;
        let (spheres, planes, cylinders) =
            build_artefacts(&raw.sphere, &raw.plane, &raw.cylinder, path)?;
        let faults = build_faults(&raw.fault, path, &machine)?;
        if let Some(home) = raw.home {
            for (axis, v) in Axis::LINEAR.into_iter().zip(home) {
                let Some(a) = machine.axis(axis) else {
                    continue;
                };
                check_range(path, &format!("home ({axis})"), v, a.min, a.max, true)?;
            }
        }
        Ok(Self {
            machine,
            seed: raw.seed,
            preset: raw.preset,
            home: raw.home,
            probe,
            truth,
            spheres,
            planes,
            cylinders,
            faults,
            path: path.to_path_buf(),
        })
    }
}

fn is_path_like(machine: &str) -> bool {
    machine.ends_with(".toml") || machine.contains('/') || machine.contains('\\')
}

fn resolve_machine(
    machine: &str,
    scenario: &Path,
    machines_dir: Option<&Path>,
) -> Result<PathBuf, ScenarioError> {
    let base = scenario.parent().unwrap_or(Path::new(""));
    if machine.trim().is_empty() {
        return Err(invalid(scenario, "machine", "is empty".into()));
    }
    if is_path_like(machine) {
        let p = Path::new(machine);
        return Ok(if p.is_absolute() {
            p.to_path_buf()
        } else {
            base.join(p)
        });
    }
    let file = format!("{machine}.toml");
    let mut tried = vec![base.join("..").join("machines").join(&file)];
    if let Some(dir) = machines_dir {
        tried.push(dir.join(&file));
        tried.push(dir.join("machines").join(&file));
    }
    if let Some(found) = tried.iter().find(|p| p.is_file()) {
        return Ok(found.clone());
    }
    let list = tried
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    Err(invalid(
        scenario,
        "machine",
        format!("no machine \"{machine}\" (looked for {list})"),
    ))
}
