//! A stylus already in contact when a move starts (a start inside material): no rising
//! probe signal will tell the collision, so the move is refused with the point before
//! anything moves, instead of pushing on until the probe's overtravel is used up and
//! the drives fault (the simulated drives send EMCY 0xFF01 then, as a broken stylus
//! would stop a real machine; a PLC fault over Modbus). On main before this check the
//! positioning move ran and ended as "drive fault (node 1, error code 0xFF01)".

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, run, tmpdir};

/// A scenario on table-ac whose plane z = 351 lies above the simulator's home
/// (Z 350): the stylus (R 3) is pressed 2 mm in before anything moves.
fn inside_material(name: &str) -> std::path::PathBuf {
    let d = tmpdir(name);
    let text = std::fs::read_to_string(configs().join("scenarios/plane-z10.toml"))
        .unwrap()
        .replace("point = [0.0, 0.0, 10.0]", "point = [0.0, 0.0, 351.0]");
    let path = d.join("inside.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `probe` from `start`, on CANopen and (`modbus`) through the simulated PLC.
fn probe(name: &str, start: &str, modbus: bool) -> (Option<i32>, String) {
    let scenario = inside_material(name);
    let mut cmd = bin();
    cmd.args(["probe", "--start", start, "--dir", "0,0,-1"]);
    if modbus {
        cmd.arg("--modbus");
    }
    let out = run(cmd
        .args(["--dist", "10", "--feed", "100"])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args([
            "--service",
            &format!("pb-defl-{name}-{}", std::process::id()),
        ]));
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_positioning_move_from_inside_material_is_refused_with_the_point() {
    // CANopen only: over Modbus a contact from before the bridge started is left to
    // the PLC (its direction is unknown to the bridge).
    let (code, err) = probe("deeper", "0,0,340", false);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(
            "already triggered at the start of the positioning move at X+0.0000 Y+0.0000 Z+350.0000"
        ) && err.contains("nothing moved")
            && !err.contains("0xFF01")
            && !err.contains("fault"),
        "{err}"
    );
}

#[test]
fn a_probing_move_from_inside_material_is_refused_with_the_point() {
    for modbus in [false, true] {
        let (code, err) = probe(&format!("probing-{modbus}"), "0,0,350", modbus);
        assert_eq!(code, Some(1), "{err}");
        assert!(
            err.contains(
                "already triggered at the start of the probing move at X+0.0000 Y+0.0000 Z+350.0000"
            ) && !err.contains("0xFF01"),
            "modbus {modbus}: {err}"
        );
    }
}
