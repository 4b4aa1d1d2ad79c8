//! Test support: an analytic machine (surfaces in closed form, no noise, not the
//! simulator) that records every move, and a machine configuration.
#![allow(dead_code)]

use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use nalgebra::Vector3;
use probebridge_cycles::CyclesConfig;
use std::path::Path;

pub const CONFIG: &str = r#"
name = "mock"
[[axis]]
name = "X"
node = 1
increments_per_unit = 10000.0
min = -1000.0
max = 1000.0
max_feed = 10000.0
max_acceleration = 2000.0
[[axis]]
name = "Y"
node = 2
increments_per_unit = 10000.0
min = -1000.0
max = 1000.0
max_feed = 10000.0
max_acceleration = 2000.0
[[axis]]
name = "Z"
node = 3
increments_per_unit = 10000.0
min = -1000.0
max = 1000.0
max_feed = 10000.0
max_acceleration = 2000.0

[[probe]]
name = "TOUCH_PROBE"
radius = 3.0
set_up = 2.0
fmax = 3000.0
f = 100.0
dist = 10.0
mb = 5.0

[[probe]]
name = "TS 460"
radius = 1.5
set_up = 1.0
fmax = 2000.0
f = 50.0
dist = 5.0
mb = 2.0

[cycles.predef]
Q320 = 0.5
Q260 = 150.0
"#;

/// [`CONFIG`] with a universal head: the spindle vertical or horizontal along X or Y.
pub fn config() -> CyclesConfig {
    let text = CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\ntool_axes = [\"Z\", \"X\", \"Y\"]\n\n[cycles.predef]",
    );
    CyclesConfig::parse(&text, Path::new("mock.toml")).unwrap()
}

/// Surfaces; normals point out of the material.
#[derive(Clone, Copy, Debug)]
pub enum Surface {
    Plane {
        point: Vector3<f64>,
        normal: Vector3<f64>,
    },
    /// Solid sphere (material inside).
    Sphere { centre: Vector3<f64>, radius: f64 },
    /// Solid cylinder about an axis through `point` along `axis` (unit).
    Cylinder {
        point: Vector3<f64>,
        axis: Vector3<f64>,
        radius: f64,
    },
}

impl Surface {
    /// Signed distance of a point from the surface (> 0 outside the material).
    fn distance(&self, x: Vector3<f64>) -> f64 {
        match *self {
            Surface::Plane { point, normal } => (x - point).dot(&normal.normalize()),
            Surface::Sphere { centre, radius } => (x - centre).norm() - radius,
            Surface::Cylinder {
                point,
                axis,
                radius,
            } => {
                let d = x - point;
                (d - axis * d.dot(&axis)).norm() - radius
            }
        }
    }

    /// Smallest t >= 0 at which a ball of radius `r` centred at `o + t d` touches.
    fn touch(&self, o: Vector3<f64>, d: Vector3<f64>, r: f64) -> Option<f64> {
        match *self {
            Surface::Plane { point, normal } => {
                let n = normal.normalize();
                let dn = d.dot(&n);
                (dn < 0.0).then(|| ((point - o).dot(&n) + r) / dn)
            }
            Surface::Sphere { centre, radius } => quadratic_root(o - centre, d, radius + r),
            Surface::Cylinder {
                point,
                axis,
                radius,
            } => {
                let p = o - point;
                let pp = p - axis * p.dot(&axis);
                let dp = d - axis * d.dot(&axis);
                quadratic_root(pp, dp, radius + r)
            }
        }
    }
}

/// Smallest t >= 0 with |p + t d| = rr.
fn quadratic_root(p: Vector3<f64>, d: Vector3<f64>, rr: f64) -> Option<f64> {
    let a = d.dot(&d);
    let b = 2.0 * p.dot(&d);
    let c = p.dot(&p) - rr * rr;
    let disc = b * b - 4.0 * a * c;
    if a == 0.0 || disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / (2.0 * a);
    (t >= 0.0).then_some(t)
}

pub struct MockMachine {
    pub pos: [f64; 3],
    pub surfaces: Vec<Surface>,
    pub ball_radius: f64,
    /// Every move: target after merging, feed.
    pub moves: Vec<([f64; 3], f64)>,
    pub probes: Vec<ProbeMove>,
    /// Make the n-th probing move (0-based) fail with this kind.
    pub fail_probe: Option<(usize, ErrorKind)>,
    sequence: u64,
}

/// How far the axes run past the contact while braking.
pub const OVERTRAVEL: f64 = 0.05;

impl MockMachine {
    pub fn new(surfaces: Vec<Surface>) -> Self {
        MockMachine {
            pos: [0.0, 0.0, 300.0],
            surfaces,
            ball_radius: 3.0,
            moves: Vec::new(),
            probes: Vec::new(),
            fail_probe: None,
            sequence: 0,
        }
    }

    pub fn motion_count(&self) -> usize {
        self.moves.len() + self.probes.len()
    }
}

impl Machine for MockMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        0b111
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        Ok(AxisPositions::linear(self.pos))
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        let p = AxisPositions::linear(self.pos).merged(target).xyz();
        self.moves.push((p, feed));
        self.pos = p;
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let index = self.probes.len();
        self.probes.push(*mv);
        if let Some((n, kind)) = self.fail_probe {
            if n == index {
                return Err(MachineError::new(kind, "injected by the test").with_node(3));
            }
        }
        let o = Vector3::from(self.pos);
        let d = Vector3::from(mv.direction).normalize();
        if self
            .surfaces
            .iter()
            .any(|s| s.distance(o) < self.ball_radius)
        {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                "ball in contact",
            ));
        }
        let hit = self
            .surfaces
            .iter()
            .filter_map(|s| s.touch(o, d, self.ball_radius))
            .filter(|t| *t <= mv.max_distance)
            .min_by(f64::total_cmp);
        let Some(t) = hit else {
            self.pos = (o + d * mv.max_distance).into();
            return Err(MachineError::new(
                ErrorKind::NotTriggered,
                format!("no contact within {:.3} mm", mv.max_distance),
            ));
        };
        let c = o + d * t;
        self.pos = (c + d * OVERTRAVEL).into();
        self.sequence += 1;
        Ok(Contact {
            positions: AxisPositions::linear(c.into()),
            trigger_ns: self.sequence * 1000,
            sequence: self.sequence,
            direction: d.into(),
        })
    }

    /// The mock publishes no samples: nothing to tag.
    fn set_run(&mut self, _run_id: u64) {}

    fn clock_ns(&mut self) -> u64 {
        0
    }
}

/// Rotation matrices written out here, independent of the crate's.
pub fn rx(deg: f64) -> nalgebra::Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    nalgebra::Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}
pub fn ry(deg: f64) -> nalgebra::Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    nalgebra::Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}
pub fn rz(deg: f64) -> nalgebra::Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    nalgebra::Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Runs a validated program on `m` with a temp output folder; confirmation answers
/// `confirm`.
pub fn run(
    program: &probebridge_cycles::Program,
    m: &mut MockMachine,
    out_dir: &Path,
    confirm: bool,
) -> (probebridge_cycles::ProgramReport, Vec<String>) {
    run_on(&config(), program, m, out_dir, confirm)
}

/// As [`run`], on the machine `cfg`.
pub fn run_on(
    cfg: &CyclesConfig,
    program: &probebridge_cycles::Program,
    m: &mut MockMachine,
    out_dir: &Path,
    confirm: bool,
) -> (probebridge_cycles::ProgramReport, Vec<String>) {
    let mut shown = Vec::new();
    let mut confirm_fn = |asked: &probebridge_cycles::confirmation::Confirmation| {
        shown.push(asked.text.clone());
        confirm
    };
    let mut progress = |_e: probebridge_cycles::ProgressEvent| {};
    let mut opts = probebridge_cycles::RunOptions {
        out_dir: out_dir.to_path_buf(),
        confirm: &mut confirm_fn,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    let report = probebridge_cycles::run_program(program, m, cfg, &mut opts);
    (report, shown)
}

/// A fresh folder under the system temp folder.
pub fn temp_dir(name: &str) -> std::path::PathBuf {
    // Unique per call: tests run in parallel and must not share (or delete) a folder.
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!(
        "probebridge-cycles-{}-{name}-{n}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
