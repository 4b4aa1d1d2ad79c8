//! The probe table and the cycles' machine parameters are read from the machine TOML
//! by this crate, as strictly as hal reads the rest: unknown keys refused, every error
//! names the file, the key and why.

mod common;

use hal::config::ConfigError;
use probebridge_cycles::CyclesConfig;
use std::path::Path;

fn parse(text: &str) -> Result<CyclesConfig, ConfigError> {
    CyclesConfig::parse(text, Path::new("m.toml"))
}

#[test]
fn probe_table_and_parameters_are_read() {
    let c = common::config();
    assert_eq!(c.probes.len(), 2);
    assert_eq!(c.probe("TS 460").unwrap().radius, 1.5);
    assert_eq!(c.parameters.predef["Q260"], 150.0);
    // Defaults of the machine parameters.
    assert_eq!(c.parameters.max_dev_cal_ball, 0.1);
    assert_eq!(c.parameters.max_modification, 0.5);
    assert_eq!(c.machine.axes.len(), 3);
}

#[test]
fn unknown_keys_in_the_cycles_sections_are_refused() {
    let text = common::CONFIG.replace("mb = 5.0", "mb = 5.0\nmbb = 1.0");
    let e = parse(&text).unwrap_err();
    assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    let e = e.to_string();
    assert!(e.contains("m.toml") && e.contains("mbb"), "{e}");

    let text = common::CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\nmaxDevCalbal = 1\n[cycles.predef]",
    );
    let e = parse(&text).unwrap_err().to_string();
    assert!(e.contains("m.toml") && e.contains("maxDevCalbal"), "{e}");
}

#[test]
fn values_out_of_range_name_file_and_key() {
    let text = common::CONFIG.replace("radius = 1.5", "radius = -1.5");
    match parse(&text).unwrap_err() {
        ConfigError::Invalid { path, key, message } => {
            assert_eq!(path, Path::new("m.toml"));
            assert_eq!(key, "probe[1] (TS 460).radius");
            assert_eq!(message, "-1.5 is outside 0.01 .. 50 mm");
        }
        e => panic!("{e}"),
    }
    let text = common::CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\nmaxModification = 0\n[cycles.predef]",
    );
    match parse(&text).unwrap_err() {
        ConfigError::Invalid { key, .. } => assert_eq!(key, "cycles.maxModification"),
        e => panic!("{e}"),
    }
}

#[test]
fn hal_still_checks_its_own_keys() {
    let text = common::CONFIG.replace("[cycles.predef]", "[cycle]\nx = 1\n[cycles.predef]");
    let e = parse(&text).unwrap_err().to_string();
    assert!(e.contains("m.toml") && e.contains("cycle"), "{e}");
}

/// Non-finite or implausible values, a probe name used twice, an unknown PREDEF
/// parameter: refused with the file, the key and why. On main before these checks all
/// of them loaded (`inf > 0` passed, names and PREDEF keys were not looked at).
#[test]
fn implausible_values_duplicate_probes_and_unknown_predef_are_refused() {
    let cases = [
        (
            common::CONFIG.replace(
                "[cycles.predef]",
                "[cycles]\nmaxModification = inf\n[cycles.predef]",
            ),
            "cycles.maxModification",
            "inf is outside 0.000001 .. 10",
        ),
        (
            common::CONFIG.replace(
                "[cycles.predef]",
                "[cycles]\nmaxDevCalBall = nan\n[cycles.predef]",
            ),
            "cycles.maxDevCalBall",
            "NaN is outside",
        ),
        (
            common::CONFIG.replace("name = \"TS 460\"", "name = \"TOUCH_PROBE\""),
            "probe[1] (TOUCH_PROBE).name",
            "also the name of probe[0]",
        ),
        (
            common::CONFIG.replace("Q260 = 150.0", "Q260 = 150.0\nQ999 = 1.0"),
            "cycles.predef.Q999",
            "Q999 is not a parameter any cycle takes as PREDEF (known: Q253, Q260, Q301, Q320)",
        ),
        (
            common::CONFIG.replace("Q320 = 0.5", "Q320 = -4.0"),
            "cycles.predef.Q320",
            "-4 is outside 0 .. 99999.9999",
        ),
        (
            common::CONFIG.replace("fmax = 3000.0", "fmax = 0.0001"),
            "probe[0] (TOUCH_PROBE).fmax",
            "0.0001 is outside 1 .. 10000 mm/min",
        ),
        (
            common::CONFIG.replace("f = 50.0", "f = 20000.0"),
            "probe[1] (TS 460).f",
            "20000 is outside 1 .. 10000 mm/min",
        ),
        (
            common::CONFIG.replace("dist = 5.0", "dist = inf"),
            "probe[1] (TS 460).dist",
            "inf is outside",
        ),
    ];
    for (text, key, why) in cases {
        match parse(&text).unwrap_err() {
            ConfigError::Invalid {
                path,
                key: k,
                message,
            } => {
                assert_eq!(path, Path::new("m.toml"));
                assert_eq!(k, key, "{message}");
                assert!(message.contains(why), "{key}: {message}");
            }
            e => panic!("{key}: not Invalid: {e}"),
        }
    }
}

#[test]
fn tool_axes_default_to_z_and_are_checked() {
    use probebridge_cycles::program::ProbeAxis;
    let c = parse(common::CONFIG).unwrap();
    assert_eq!(c.parameters.tool_axes, [ProbeAxis::Z]);
    let text = common::CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\ntool_axes = [\"Y\", \"Z\"]\n[cycles.predef]",
    );
    assert_eq!(
        parse(&text).unwrap().parameters.tool_axes,
        [ProbeAxis::Y, ProbeAxis::Z]
    );
    let text = common::CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\ntool_axes = []\n[cycles.predef]",
    );
    match parse(&text).unwrap_err() {
        ConfigError::Invalid { key, message, .. } => {
            assert_eq!(key, "cycles.tool_axes");
            assert!(message.contains("at least one"), "{message}");
        }
        e => panic!("{e}"),
    }
    let text = common::CONFIG.replace(
        "[cycles.predef]",
        "[cycles]\ntool_axes = [\"W\"]\n[cycles.predef]",
    );
    let e = parse(&text).unwrap_err().to_string();
    assert!(
        e.contains("m.toml") && e.contains("tool_axes") && e.contains("W"),
        "{e}"
    );
}
