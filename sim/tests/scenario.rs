//! Scenario parsing: strict keys, ranges, and every shipped scenario validates.

mod common;

use common::{configs_dir, machine, scenario, scenario_error};
use hal::Axis;
use probebridge_sim::{Scenario, World};
use std::path::Path;

const PROBE: &str = "[probe]\nball_radius = 3.0\n";

fn assert_err(body: &str, needles: &[&str]) {
    let e = scenario_error(body);
    assert!(e.contains("bad.toml"), "{e}");
    for n in needles {
        assert!(e.contains(n), "missing {n:?} in: {e}");
    }
}

#[test]
fn full_example_parses() {
    let s = scenario(
        "table-ac",
        r#"
seed = 1
[probe]
ball_radius = 3.0
noise = 0.0
pretravel = 0.0
table_radius = 2.998
[truth]
EX0C = 0.012
EB0A = 0.005
EC0C = 0.004
backlash_C = 0.01
hirth_C = 0.0
[[sphere]]
center = [0.0, 0.0, 100.0]
radius = 12.5
[[plane]]
point = [0.0, 0.0, 10.0]
normal = [0.0, 0.0, 2.0]
[[cylinder]]
point = [1.0, 2.0, 3.0]
direction = [0.0, 1.0, 0.0]
radius = 5
[[fault]]
node = 1
kind = "emcy"
after_ms = 100.0
code = 0x8611
[[fault]]
node = 5
kind = "silent"
after_ms = 5
"#,
    );
    assert_eq!(s.seed, 1);
    assert_eq!(s.truth.get("EX0C"), Some(0.012));
    assert_eq!(s.truth.c.position, [0.012, 0.0]);
    assert_eq!(s.truth.a.orientation, [0.005, 0.0]);
    assert_eq!(s.truth.c.zero, 0.004);
    assert_eq!(s.truth.c.backlash, 0.01);
    assert_eq!(s.truth.location_errors(Axis::C), [0.012, 0.0, 0.0, 0.0]);
    assert_eq!(s.hirth(Axis::C), 0.0);
    assert_eq!(s.probe_table_radius(), 2.998);
    assert_eq!(
        (s.spheres.len(), s.planes.len(), s.cylinders.len()),
        (1, 1, 1)
    );
    assert_eq!(s.planes[0].normal.z, 1.0);
    assert_eq!(s.faults.len(), 2);
    assert_eq!(s.faults[0].code, Some(0x8611));
    assert_eq!(s.faults[1].code, None);
    assert_eq!(s.path, Path::new("test.toml"));
}

#[test]
fn defaults() {
    let s = scenario("table-ac", PROBE);
    assert_eq!(s.seed, 0);
    assert_eq!(
        (s.probe.noise, s.probe.pretravel, s.probe.table_radius),
        (0.0, 0.0, None)
    );
    assert_eq!(s.probe_table_radius(), 3.0);
    assert_eq!(s.truth, Default::default());
}

#[test]
fn unknown_keys_are_named() {
    assert_err(&format!("{PROBE}sed = 1\n"), &["sed"]);
    assert_err(
        "[probe]\nball_radius = 3.0\nball_radus = 2.0\n",
        &["ball_radus"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nEX0Z = 0.1\n"),
        &["truth.EX0Z", "unknown key"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nex0c = 0.1\n"),
        &["truth.ex0c", "did you mean EX0C"],
    );
    assert_err(
        &format!("{PROBE}[[sphere]]\ncentre = [0.0, 0.0, 0.0]\nradius = 1.0\n"),
        &["centre"],
    );
    assert_err(
        &format!("{PROBE}[[fault]]\nnode = 1\nkind = \"boom\"\nafter_ms = 1.0\n"),
        &["boom"],
    );
}

#[test]
fn out_of_range_values_are_named() {
    assert_err(
        "[probe]\nball_radius = -3.0\n",
        &["probe.ball_radius", "-3"],
    );
    assert_err(
        "[probe]\nball_radius = 3.0\nnoise = -0.1\n",
        &["probe.noise"],
    );
    assert_err(
        "[probe]\nball_radius = 3.0\npretravel = 3.0\n",
        &["probe.pretravel", "ball_radius"],
    );
    assert_err(
        "[probe]\nball_radius = 3.0\ntable_radius = 0.0\n",
        &["probe.table_radius"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nEX0C = 11.0\n"),
        &["truth.EX0C", "out of range"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nEB0A = -20.0\n"),
        &["truth.EB0A", "deg"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nbacklash_C = -0.1\n"),
        &["truth.backlash_C"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nhirth_C = 7.0\n"),
        &["truth.hirth_C", "does not divide 360"],
    );
    assert_err(
        &format!("{PROBE}[[sphere]]\ncenter = [0.0, 0.0, 0.0]\nradius = 0.0\n"),
        &["sphere[0].radius"],
    );
    assert_err(
        &format!("{PROBE}[[plane]]\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 0.0]\n"),
        &["plane[0].normal", "zero"],
    );
    assert_err(
        &format!("{PROBE}[[cylinder]]\npoint = [0.0, 0.0, 0.0]\ndirection = [0.0, 0.0, 0.0]\nradius = 1.0\n"),
        &["cylinder[0].direction"],
    );
    assert_err(
        &format!("{PROBE}[[fault]]\nnode = 9\nkind = \"emcy\"\nafter_ms = 1.0\n"),
        &["fault[0].node", "node 9"],
    );
    assert_err(
        &format!("{PROBE}[[fault]]\nnode = 1\nkind = \"silent\"\nafter_ms = 1.0\ncode = 1\n"),
        &["fault[0].code"],
    );
    assert_err(
        &format!("{PROBE}[[fault]]\nnode = 1\nkind = \"emcy\"\nafter_ms = -1.0\n"),
        &["fault[0].after_ms"],
    );
    assert_err("seed = 1\n", &["probe"]);
}

#[test]
fn errors_for_missing_axes_are_refused() {
    // table-ac has no B axis.
    assert_err(
        &format!("{PROBE}[truth]\nEB0B = 0.01\n"),
        &["truth.EB0B", "no B axis"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nEZ0B = 0.0\n"),
        &["truth.EZ0B", "no B axis"],
    );
    assert_err(
        &format!("{PROBE}[truth]\nbacklash_B = 0.01\n"),
        &["truth.backlash_B"],
    );
    // head-b-table-c has no A axis.
    let text = format!("machine = \"head-b-table-c\"\n{PROBE}[truth]\nEY0A = 0.01\n");
    let e = Scenario::parse_with_machine(&text, Path::new("hb.toml"), machine("head-b-table-c"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("hb.toml") && e.contains("truth.EY0A") && e.contains("no A axis"),
        "{e}"
    );
}

#[test]
fn machine_references_resolve() {
    let dir = configs_dir().join("scenarios");
    // By name, next to the scenario folder.
    let s = Scenario::parse(
        &format!("machine = \"table-ac\"\n{PROBE}"),
        &dir.join("x.toml"),
        None,
    )
    .unwrap();
    assert_eq!(s.machine.name, "table-ac");
    // By name via the given configs dir when the scenario lives elsewhere.
    let elsewhere = Path::new("/nonexistent/x.toml");
    let text = format!("machine = \"head-b-table-c\"\n{PROBE}");
    assert!(Scenario::parse(&text, elsewhere, Some(&configs_dir())).is_ok());
    assert!(Scenario::parse(&text, elsewhere, Some(&configs_dir().join("machines"))).is_ok());
    let e = Scenario::parse(&text, elsewhere, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("machine") && e.contains("head-b-table-c"), "{e}");
    // By relative path.
    let text = format!("machine = \"../machines/table-ac.toml\"\n{PROBE}");
    assert!(Scenario::parse(&text, &dir.join("x.toml"), None).is_ok());
    // The bare name must match a machine given directly.
    let e = Scenario::parse_with_machine(
        &format!("machine = \"other\"\n{PROBE}"),
        Path::new("m.toml"),
        machine("table-ac"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("machine") && e.contains("other"), "{e}");
}

#[test]
fn every_shipped_scenario_validates() {
    let dir = configs_dir().join("scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let s = Scenario::load(&path, Some(&configs_dir())).unwrap_or_else(|e| panic!("{e}"));
            // And the world builds and answers.
            let w = World::new(&s);
            let _ = w.deflected(&hal::AxisPositions::linear([0.0, 0.0, 300.0]));
            n += 1;
        }
    }
    assert!(n >= 5, "only {n} scenarios in {}", dir.display());
}

#[test]
fn sphere_scenarios_put_the_sphere_where_they_say_at_zero() {
    // Location errors only: at all-zero rotary axes the table frame is the machine frame.
    for name in ["demo-sphere.toml", "head-b-table-c.toml"] {
        let s = Scenario::load(&configs_dir().join("scenarios").join(name), None).unwrap();
        assert!(s.truth != Default::default(), "{name} injects errors");
        let w = World::new(&s);
        let c = s.spheres[0].center;
        let mut at = hal::AxisPositions::linear([c.x, c.y, c.z + 15.5]);
        for a in [Axis::A, Axis::B, Axis::C] {
            if s.machine.axis(a).is_some() {
                at.set(a, 0.0);
            }
        }
        let got = w.ball_centre_in_table(&at);
        assert!(
            (got - nalgebra::Vector3::new(c.x, c.y, c.z + 15.5)).norm() < 1e-12,
            "{name}"
        );
        // ...and a turned rotary axis does see the errors.
        let turned = at.with(Axis::C, 90.0);
        let nominal = probebridge_sim::kinematics::TrueKinematics::nominal(&s.machine);
        let d = (w.ball_centre_in_table(&turned) - nominal.ball_centre_in_table(&turned)).norm();
        assert!(d > 1e-3, "{name}: {d}");
    }
}

#[test]
fn errors_carry_their_kind() {
    use hal::config::ConfigErrorKind;
    let parse = |body: &str| {
        let text = format!("machine = \"table-ac\"\n{body}");
        Scenario::parse_with_machine(&text, Path::new("bad.toml"), machine("table-ac"))
            .map(|_| ())
            .unwrap_err()
            .kind()
    };
    assert_eq!(
        parse("[probe]\nball_radius = 3.0\nnoize = 0.1\n"),
        ConfigErrorKind::Parse
    );
    assert_eq!(
        parse("[probe]\nball_radius = -3.0\n"),
        ConfigErrorKind::Invalid
    );
    let missing = Scenario::load(Path::new("/nonexistent/scenario.toml"), None).unwrap_err();
    assert_eq!(missing.kind(), ConfigErrorKind::Read);
}

#[test]
fn home_is_where_the_axes_start_inside_the_software_limits() {
    use probebridge_sim::machine::SimMachine;
    let s = scenario("table-ac", PROBE);
    assert_eq!(s.home, None);
    // The default: a vertical spindle 50 mm below its top.
    let start = SimMachine::start_positions(&s);
    assert_eq!(start.get(Axis::Z), Some(350.0));
    let s = scenario("table-ac", &format!("home = [1.0, 250.0, -2.0]\n{PROBE}"));
    let start = SimMachine::start_positions(&s);
    assert_eq!(start.xyz(), [1.0, 250.0, -2.0]);
    assert_err(
        &format!("home = [0.0, 301.0, 0.0]\n{PROBE}"),
        &["home (Y)", "301"],
    );
}
