//! The TOML files a user writes: machine (hal's part and the cycles'), scenario,
//! preset table, active kinematics, gateway; and the candump log.

use super::{accepted_finite, text};
use crate::corpus;
use crate::driver::Target;
use crate::sig::Sig;
use cycles::kinematics_file::ActiveKinematics;
use cycles::preset_table::PresetTable;
use cycles::CyclesConfig;
use hal::can::candump;
use hal::config::MachineConfig;
use probebridge::serve::config::GatewayConfig;
use sim::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const TOML_TOKENS: &[&str] = &[
    "[bus]",
    "[[axis]]",
    "[[probe]]",
    "[cycles]",
    "[truth]",
    "[probe]",
    "[[sphere]]",
    "[[plane]]",
    "[[fault]]",
    "[errors]",
    "[machine]",
    "[plc]",
    "[programs]",
    "[history]",
    // The cycles' keys of issue 27, which no shipped machine sets.
    "[cycles.errors]",
    "1001 = \"dispersion too large\"",
    "mStrobeRotAxPos = 203",
    "max_jumps = 0",
    // The spindle drive (issue 22); table-ac sets it, the others do not.
    "[spindle]",
    "node = 127",
    "increments_per_degree = 0",
    "orient_rpm = 1e9",
    "spindle_orientation = true",
    "kind = \"canopen\"",
    "kind = \"modbus\"",
    " = ",
    "\"",
    "'''",
    "[",
    "]",
    "{",
    "}",
    ",",
    "true",
    "false",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-0.0",
    "0x7F",
    "1979-05-27",
    "\\u0000",
    "#",
    "\n",
    ".",
];

pub fn targets() -> Vec<Target> {
    vec![
        Target {
            name: "machine-toml",
            about: "machine TOML: hal's validation, then the cycles' ([[probe]], [cycles], the preset table beside it)",
            max_len: 16 * 1024,
            prepare: || {},
            seeds: || corpus::files(&corpus::configs("machines"), ".toml"),
            dictionary: TOML_TOKENS,
            run: run_machine,
        },
        Target {
            name: "scenario-toml",
            about: "scenario TOML validated against its machine",
            max_len: 16 * 1024,
            prepare: || {
                machines();
            },
            seeds: || corpus::files(&corpus::configs("scenarios"), ".toml"),
            dictionary: TOML_TOKENS,
            run: run_scenario,
        },
        Target {
            name: "presets-toml",
            about: "the preset table of a machine",
            max_len: 8 * 1024,
            prepare: || {
                machines();
            },
            seeds: || {
                corpus::with(
                    corpus::files(&corpus::configs("machines"), ".presets.toml"),
                    &["machine = \"table-ac\"\nactive = 0\n[[preset]]\nnumber = 0\nx = 1.5\nc = 90.0\n"],
                )
            },
            dictionary: TOML_TOKENS,
            run: run_presets,
        },
        Target {
            name: "kinematics-toml",
            about: "the active kinematics file cycle 451 reads and writes",
            max_len: 8 * 1024,
            prepare: || {
                machines();
            },
            seeds: || {
                corpus::with(
                    Vec::new(),
                    &[
                        "machine = \"table-ac\"\n[errors]\nEX0C = 0.01\nEY0C = -0.02\nEA0A = 0.001\n",
                        "machine = \"head-b-table-c\"\n[errors]\nEZ0B = 0.5\nEB0C = 0.0\n",
                        "machine = \"table-ac\"\n",
                    ],
                )
            },
            dictionary: TOML_TOKENS,
            run: run_kinematics,
        },
        Target {
            name: "gateway-toml",
            about: "the gateway service configuration",
            max_len: 8 * 1024,
            prepare: || {},
            seeds: || corpus::files(&corpus::configs(""), ".toml"),
            dictionary: TOML_TOKENS,
            run: run_gateway,
        },
        Target {
            name: "candump",
            about: "candump -L logs; every frame read is written back and read again unchanged (to the microsecond)",
            max_len: 8 * 1024,
            prepare: || {},
            seeds: || {
                corpus::with(
                    corpus::files(&corpus::workspace().join("tests/data"), ".log"),
                    &[
                        "(1700000000.000001) can0 181#0102030405060708\n",
                        "(0.1) vcan0 000#0101 R\n(0.2) vcan0 601#R8 T\n# comment\n\n",
                        "(1.000000000) can0 7FF#\n(18446744073.709551615) can0 080#00.11.22\n",
                        "(1.5) can0 12345678#00\n(1.5) can0 123##100\n",
                    ],
                )
            },
            dictionary: &["(", ")", "#", "##", ".", "R", "T", " ", "\t", "can0", "7FF", "800", "\n"],
            run: run_candump,
        },
    ]
}

/// The machines a scenario, preset table or kinematics file may name.
fn machines() -> &'static [MachineConfig] {
    static M: OnceLock<Vec<MachineConfig>> = OnceLock::new();
    M.get_or_init(|| {
        [
            "table-ac.toml",
            "head-b-table-c.toml",
            "table-ac-modbus.toml",
        ]
        .iter()
        .map(|name| {
            let path = corpus::configs("machines").join(name);
            MachineConfig::load(&path).unwrap_or_else(|e| panic!("fuzz: {}: {e}", path.display()))
        })
        .collect()
    })
}

/// The machine whose name the text mentions (the longest match), else the first.
fn machine_for(text: &str) -> &'static MachineConfig {
    let m = machines();
    m.iter()
        .filter(|c| text.contains(c.name.as_str()))
        .max_by_key(|c| c.name.len())
        .unwrap_or(&m[0])
}

/// A source path in a folder that does not exist: nothing beside it is found.
fn source(name: &str) -> PathBuf {
    Path::new("/nonexistent-probebridge-fuzz").join(name)
}

fn outcome<T, E: std::fmt::Display>(r: &Result<T, E>) -> Sig {
    let mut sig = Sig::default();
    match r {
        Ok(_) => sig.text("ok"),
        Err(e) => sig.message(&e.to_string()),
    };
    sig
}

fn run_machine(data: &[u8]) -> Sig {
    let t = text(data);
    let r = CyclesConfig::parse(&t, &source("machine.toml"));
    accepted_finite(&r, "machine TOML");
    match &r {
        // Keys can hold the input's own names (`cycles.predef.Q320`): the section and
        // the reason are the outcome.
        Err(hal::config::ConfigError::Invalid { key, message, .. }) => {
            let section = key.split(['.', '[']).next().unwrap_or("");
            let mut sig = Sig::default();
            sig.text(section).message(message);
            sig
        }
        _ => outcome(&r),
    }
}

fn run_scenario(data: &[u8]) -> Sig {
    let t = text(data);
    let machine = machine_for(&t).clone();
    let r = Scenario::parse_with_machine(&t, &source("scenario.toml"), machine);
    accepted_finite(&r, "scenario");
    outcome(&r)
}

fn run_presets(data: &[u8]) -> Sig {
    let t = text(data);
    let r = PresetTable::parse(&t, &source("m.presets.toml"), machine_for(&t));
    accepted_finite(&r, "preset table");
    if let Ok(table) = &r {
        // What was accepted is written back as the same table.
        let again =
            PresetTable::parse(&table.to_toml(), &source("m.presets.toml"), machine_for(&t));
        assert!(
            again.as_ref().is_ok_and(|a| a.to_toml() == table.to_toml()),
            "preset table does not survive writing and reading: {again:?}"
        );
    }
    outcome(&r)
}

fn run_kinematics(data: &[u8]) -> Sig {
    let t = text(data);
    let r = ActiveKinematics::parse(&t, &source("m.kinematics.toml"), machine_for(&t));
    accepted_finite(&r, "kinematics file");
    outcome(&r)
}

fn run_gateway(data: &[u8]) -> Sig {
    let t = text(data);
    let r = GatewayConfig::parse(&t, &source("gateway.toml"));
    accepted_finite(&r, "gateway configuration");
    if let Ok(cfg) = &r {
        let mut sig = Sig::default();
        sig.debug(&cfg.listen().map(|_| ()))
            .debug(&cfg.word_order().map(|_| ()))
            .debug(&cfg.heartbeat_timeout().is_some());
        return sig;
    }
    outcome(&r)
}

fn run_candump(data: &[u8]) -> Sig {
    let t = text(data);
    let r = candump::parse_log(&t);
    if let Ok(frames) = &r {
        for (ts, iface, frame) in frames {
            let line = candump::format_line(*ts, iface, frame);
            let back = candump::parse_line(&line);
            assert!(
                // Written in microseconds, as candump does.
                back.as_ref()
                    .is_ok_and(|(t, i, f)| *t == ts / 1000 * 1000 && i == iface && f == frame),
                "candump line {line:?} reads back as {back:?}"
            );
        }
        let mut sig = Sig::default();
        sig.text("ok").value(frames.len().min(4) as u64);
        return sig;
    }
    outcome(&r)
}
