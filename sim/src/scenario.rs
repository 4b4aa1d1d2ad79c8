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

use crate::artefact::{Cylinder, Plane, Sphere};
use hal::config::{ConfigError, MachineConfig};
use hal::Axis;
use nalgebra::Vector3;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The scenario file itself: unreadable, not TOML, or a key out of range; the
    /// same errors as a machine configuration's, naming the scenario file.
    #[error(transparent)]
    File(#[from] ConfigError),
    /// The machine configuration the scenario names.
    #[error("{path}: machine: {source}")]
    Machine { path: PathBuf, source: ConfigError },
}

impl ScenarioError {
    /// The kind of the scenario's or its machine's error.
    pub fn kind(&self) -> hal::config::ConfigErrorKind {
        match self {
            ScenarioError::File(e) | ScenarioError::Machine { source: e, .. } => e.kind(),
        }
    }
}

/// The real probe (what the probe table only approximates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTruth {
    /// True stylus ball radius, mm.
    pub ball_radius: f64,
    /// Trigger noise, 1 sigma along the probing direction, mm.
    pub noise: f64,
    /// Deflection beyond first touch before the signal switches, mm.
    pub pretravel: f64,
    /// R written into the probe table; `None` = `ball_radius` (a calibrated probe).
    pub table_radius: Option<f64>,
}

/// The true errors of one rotary axis (ISO 230-7).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RotaryTruth {
    /// Position errors of the axis line, mm, in QS order
    /// (A: EY0A, EZ0A; B: EZ0B, EX0B; C: EX0C, EY0C).
    pub position: [f64; 2],
    /// Orientation errors of the axis direction, deg, in QS order
    /// (A: EB0A, EC0A; B: EC0B, EA0B; C: EA0C, EB0C).
    pub orientation: [f64; 2],
    /// Zero-position error (EA0A / EB0B / EC0C), deg: added to the mechanical angle.
    pub zero: f64,
    /// Width of the backlash dead band, deg.
    pub backlash: f64,
    /// Hirth grid, deg; `Some(0.0)` = none; `None` = the machine config's `hirth`.
    pub hirth: Option<f64>,
}

impl RotaryTruth {
    /// Position errors as the offset of the axis line from its pivot, mm
    /// (A: (0, EY0A, EZ0A); B: (EX0B, 0, EZ0B); C: (EX0C, EY0C, 0)).
    pub fn offset(&self, axis: Axis) -> Vector3<f64> {
        let [p0, p1] = self.position;
        match axis {
            Axis::A => Vector3::new(0.0, p0, p1),
            Axis::B => Vector3::new(p1, 0.0, p0),
            Axis::C => Vector3::new(p0, p1, 0.0),
            _ => Vector3::zeros(),
        }
    }

    /// The four location errors in the QS string order of spec.md.
    pub fn location_errors(&self) -> [f64; 4] {
        [
            self.position[0],
            self.position[1],
            self.orientation[0],
            self.orientation[1],
        ]
    }
}

/// Per-axis kinds of truth keys; `Truth::KEYS` maps every key name to one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    Position(usize),
    Orientation(usize),
    Zero,
    Backlash,
    Hirth,
}

/// The truth of all rotary axes; axes the machine lacks stay at zero.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    pub a: RotaryTruth,
    pub b: RotaryTruth,
    pub c: RotaryTruth,
}

impl Truth {
    /// Every key `[truth]` accepts, with its axis.
    const KEYS: [(&'static str, Axis, Field); 21] = [
        ("EY0A", Axis::A, Field::Position(0)),
        ("EZ0A", Axis::A, Field::Position(1)),
        ("EB0A", Axis::A, Field::Orientation(0)),
        ("EC0A", Axis::A, Field::Orientation(1)),
        ("EZ0B", Axis::B, Field::Position(0)),
        ("EX0B", Axis::B, Field::Position(1)),
        ("EC0B", Axis::B, Field::Orientation(0)),
        ("EA0B", Axis::B, Field::Orientation(1)),
        ("EX0C", Axis::C, Field::Position(0)),
        ("EY0C", Axis::C, Field::Position(1)),
        ("EA0C", Axis::C, Field::Orientation(0)),
        ("EB0C", Axis::C, Field::Orientation(1)),
        ("EA0A", Axis::A, Field::Zero),
        ("EB0B", Axis::B, Field::Zero),
        ("EC0C", Axis::C, Field::Zero),
        ("backlash_A", Axis::A, Field::Backlash),
        ("backlash_B", Axis::B, Field::Backlash),
        ("backlash_C", Axis::C, Field::Backlash),
        ("hirth_A", Axis::A, Field::Hirth),
        ("hirth_B", Axis::B, Field::Hirth),
        ("hirth_C", Axis::C, Field::Hirth),
    ];

    pub fn axis(&self, axis: Axis) -> Option<&RotaryTruth> {
        match axis {
            Axis::A => Some(&self.a),
            Axis::B => Some(&self.b),
            Axis::C => Some(&self.c),
            _ => None,
        }
    }

    fn axis_mut(&mut self, axis: Axis) -> Option<&mut RotaryTruth> {
        match axis {
            Axis::A => Some(&mut self.a),
            Axis::B => Some(&mut self.b),
            Axis::C => Some(&mut self.c),
            _ => None,
        }
    }

    /// Value of a `[truth]` key by name ("EX0C", "backlash_C", ...); `hirth_*` reads
    /// 0 when absent. `None` for an unknown name.
    pub fn get(&self, key: &str) -> Option<f64> {
        let (_, axis, field) = Self::KEYS.iter().find(|(k, ..)| *k == key)?;
        let t = self.axis(*axis)?;
        Some(match field {
            Field::Position(i) => t.position[*i],
            Field::Orientation(i) => t.orientation[*i],
            Field::Zero => t.zero,
            Field::Backlash => t.backlash,
            Field::Hirth => t.hirth.unwrap_or(0.0),
        })
    }

    /// Sets a `[truth]` key by name; `false` for an unknown name.
    pub fn set(&mut self, key: &str, value: f64) -> bool {
        let Some((_, axis, field)) = Self::KEYS.iter().find(|(k, ..)| *k == key) else {
            return false;
        };
        let Some(t) = self.axis_mut(*axis) else {
            return false;
        };
        match field {
            Field::Position(i) => t.position[*i] = value,
            Field::Orientation(i) => t.orientation[*i] = value,
            Field::Zero => t.zero = value,
            Field::Backlash => t.backlash = value,
            Field::Hirth => t.hirth = Some(value),
        }
        true
    }

    /// The four location errors of `axis` in QS string order (zeros for X/Y/Z).
    pub fn location_errors(&self, axis: Axis) -> [f64; 4] {
        self.axis(axis)
            .map(RotaryTruth::location_errors)
            .unwrap_or_default()
    }

    fn accepted_keys() -> String {
        Self::KEYS
            .iter()
            .map(|(k, ..)| *k)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// What the drive simulation does to a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// The drive reports an emergency (EMCY) and goes to Fault.
    Emcy,
    /// The node stops answering (no heartbeat, no PDO, no SDO).
    Silent,
    /// The node restarts (as after a watchdog reset or a power dip): boot-up frame,
    /// configuration back to defaults, pre-operational.
    Reboot,
}

/// A fault the drive simulation injects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// CANopen node of an axis of the machine.
    pub node: u8,
    pub kind: FaultKind,
    /// Time after the simulation starts, ms.
    pub after_ms: f64,
    /// EMCY error code (emcy only); `None` = the drive simulation's default.
    pub code: Option<u16>,
}

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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProbe {
    ball_radius: f64,
    #[serde(default)]
    noise: f64,
    #[serde(default)]
    pretravel: f64,
    table_radius: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSphere {
    center: [f64; 3],
    radius: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlane {
    point: [f64; 3],
    normal: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCylinder {
    point: [f64; 3],
    direction: [f64; 3],
    radius: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFault {
    node: u8,
    kind: FaultKind,
    after_ms: f64,
    code: Option<u16>,
}

/// Largest accepted magnitudes of the truth values: beyond them a scenario is a typo,
/// not a machine (position mm, angles deg).
const MAX_POSITION_ERROR: f64 = 10.0;
const MAX_ANGLE_ERROR: f64 = 10.0;
/// Same range as Q432 (backlash measuring range).
const MAX_BACKLASH: f64 = 3.0;
const MAX_BALL_RADIUS: f64 = 50.0;
const MAX_NOISE: f64 = 1.0;

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
        let (spheres, planes, cylinders) = build_artefacts(&raw, path)?;
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

/// `[probe]`: the real probe.
fn build_probe(p: &RawProbe, path: &Path) -> Result<ProbeTruth, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    check_range(
        path,
        "probe.ball_radius",
        p.ball_radius,
        0.0,
        MAX_BALL_RADIUS,
        false,
    )?;
    check_range(path, "probe.noise", p.noise, 0.0, MAX_NOISE, true)?;
    if !(p.pretravel.is_finite() && p.pretravel >= 0.0 && p.pretravel < p.ball_radius) {
        return Err(bad(
            "probe.pretravel",
            format!(
                "{} must be >= 0 and smaller than ball_radius ({})",
                p.pretravel, p.ball_radius
            ),
        ));
    }
    if let Some(r) = p.table_radius {
        check_range(path, "probe.table_radius", r, 0.0, MAX_BALL_RADIUS, false)?;
    }
    Ok(ProbeTruth {
        ball_radius: p.ball_radius,
        noise: p.noise,
        pretravel: p.pretravel,
        table_radius: p.table_radius,
    })
}

/// `[truth]`: the machine's true errors, each on an axis the machine has.
fn build_truth(
    raw: &BTreeMap<String, f64>,
    path: &Path,
    machine: &MachineConfig,
) -> Result<Truth, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let mut truth = Truth::default();
    for (key, &value) in raw {
        let Some((_, axis, field)) = Truth::KEYS.iter().find(|(k, ..)| k == key) else {
            let hint = Truth::KEYS
                .iter()
                .find(|(k, ..)| k.eq_ignore_ascii_case(key))
                .map(|(k, ..)| format!(" (did you mean {k}?)"))
                .unwrap_or_default();
            return Err(bad(
                &format!("truth.{key}"),
                format!("unknown key{hint}; accepted: {}", Truth::accepted_keys()),
            ));
        };
        let key = format!("truth.{key}");
        if machine.axis(*axis).is_none() {
            return Err(bad(
                &key,
                format!("machine \"{}\" has no {axis} axis", machine.name),
            ));
        }
        match field {
            Field::Position(_) => check_abs(path, &key, value, MAX_POSITION_ERROR, "mm")?,
            Field::Orientation(_) | Field::Zero => {
                check_abs(path, &key, value, MAX_ANGLE_ERROR, "deg")?
            }
            Field::Backlash => check_range(path, &key, value, 0.0, MAX_BACKLASH, true)?,
            Field::Hirth => check_hirth(path, &key, value)?,
        }
        truth.set(&key["truth.".len()..], value);
    }
    Ok(truth)
}

type Artefacts = (Vec<Sphere>, Vec<Plane>, Vec<Cylinder>);

/// `[[sphere]]`, `[[plane]]`, `[[cylinder]]`.
fn build_artefacts(raw: &RawScenario, path: &Path) -> Result<Artefacts, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let vec3 = |v: [f64; 3]| Vector3::new(v[0], v[1], v[2]);
    let mut spheres = Vec::with_capacity(raw.sphere.len());
    for (i, s) in raw.sphere.iter().enumerate() {
        check_finite3(path, &format!("sphere[{i}].center"), s.center)?;
        check_range(
            path,
            &format!("sphere[{i}].radius"),
            s.radius,
            0.0,
            1e4,
            false,
        )?;
        spheres.push(Sphere::new(vec3(s.center), s.radius).expect("validated above"));
    }
    let mut planes = Vec::with_capacity(raw.plane.len());
    for (i, s) in raw.plane.iter().enumerate() {
        check_finite3(path, &format!("plane[{i}].point"), s.point)?;
        check_finite3(path, &format!("plane[{i}].normal"), s.normal)?;
        planes.push(
            Plane::new(vec3(s.point), vec3(s.normal))
                .ok_or_else(|| bad(&format!("plane[{i}].normal"), "must not be zero".into()))?,
        );
    }
    let mut cylinders = Vec::with_capacity(raw.cylinder.len());
    for (i, s) in raw.cylinder.iter().enumerate() {
        check_finite3(path, &format!("cylinder[{i}].point"), s.point)?;
        check_finite3(path, &format!("cylinder[{i}].direction"), s.direction)?;
        check_range(
            path,
            &format!("cylinder[{i}].radius"),
            s.radius,
            0.0,
            1e4,
            false,
        )?;
        cylinders.push(
            Cylinder::new(vec3(s.point), vec3(s.direction), s.radius).ok_or_else(|| {
                bad(
                    &format!("cylinder[{i}].direction"),
                    "must not be zero".into(),
                )
            })?,
        );
    }
    Ok((spheres, planes, cylinders))
}

/// `[[fault]]`: each on a node of the machine.
fn build_faults(
    raw: &[RawFault],
    path: &Path,
    machine: &MachineConfig,
) -> Result<Vec<Fault>, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let mut faults = Vec::with_capacity(raw.len());
    for (i, f) in raw.iter().enumerate() {
        if !machine.axes.iter().any(|a| a.node == Some(f.node)) {
            return Err(bad(
                &format!("fault[{i}].node"),
                format!(
                    "no axis of machine \"{}\" is on node {}",
                    machine.name, f.node
                ),
            ));
        }
        check_range(
            path,
            &format!("fault[{i}].after_ms"),
            f.after_ms,
            0.0,
            1e9,
            true,
        )?;
        if f.code.is_some() && f.kind != FaultKind::Emcy {
            return Err(bad(
                &format!("fault[{i}].code"),
                "only an \"emcy\" fault has an error code".into(),
            ));
        }
        faults.push(Fault {
            node: f.node,
            kind: f.kind,
            after_ms: f.after_ms,
            code: f.code,
        });
    }
    Ok(faults)
}

/// Hirth grid of `axis` used by the physics: the truth's when given, else the
/// machine configuration's.
pub(crate) fn effective_hirth(machine: &MachineConfig, truth: &Truth, axis: Axis) -> f64 {
    truth
        .axis(axis)
        .and_then(|t| t.hirth)
        .or_else(|| machine.axis(axis).map(|a| a.hirth))
        .unwrap_or(0.0)
}

fn invalid(path: &Path, key: &str, message: String) -> ScenarioError {
    ConfigError::Invalid {
        path: path.to_path_buf(),
        key: key.to_string(),
        message,
    }
    .into()
}

/// `lo < v <= hi` (or `lo <= v` when `lo_inclusive`), finite.
fn check_range(
    path: &Path,
    key: &str,
    v: f64,
    lo: f64,
    hi: f64,
    lo_inclusive: bool,
) -> Result<(), ScenarioError> {
    let ok = v.is_finite() && (if lo_inclusive { v >= lo } else { v > lo }) && v <= hi;
    if ok {
        return Ok(());
    }
    let lo_txt = if lo_inclusive { ">=" } else { ">" };
    Err(invalid(
        path,
        key,
        format!("{v} is out of range (must be {lo_txt} {lo} and <= {hi})"),
    ))
}

fn check_abs(path: &Path, key: &str, v: f64, max: f64, unit: &str) -> Result<(), ScenarioError> {
    if v.is_finite() && v.abs() <= max {
        return Ok(());
    }
    Err(invalid(
        path,
        key,
        format!("{v} is out of range (|value| <= {max} {unit})"),
    ))
}

fn check_hirth(path: &Path, key: &str, v: f64) -> Result<(), ScenarioError> {
    check_range(path, key, v, 0.0, 90.0, true)?;
    if v > 0.0 {
        let teeth = 360.0 / v;
        if (teeth - teeth.round()).abs() > 1e-9 {
            return Err(invalid(
                path,
                key,
                format!("a Hirth grid of {v} deg does not divide 360 deg"),
            ));
        }
    }
    Ok(())
}

fn check_finite3(path: &Path, key: &str, v: [f64; 3]) -> Result<(), ScenarioError> {
    if v.iter().all(|x| x.is_finite()) {
        return Ok(());
    }
    Err(invalid(path, key, format!("{v:?} is not finite")))
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
