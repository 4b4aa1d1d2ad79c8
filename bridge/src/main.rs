//! The `probebridge` command line.

use clap::{Args, CommandFactory, Parser, Subcommand};
use probebridge::commands::{self, parse_vec3};
use probebridge::session::options::MachineOptions;
use probebridge::tell;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "probebridge",
    version,
    about = "Touch-probe measuring cycles (TNC 451/450/431/444) for fieldbus-driven machines"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Args, Clone)]
struct MachineArgs {
    /// Simulation scenario (TOML); default: configs/scenarios/demo-sphere.toml.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Machine configuration (TOML) of real drives on --can, instead of a scenario.
    #[arg(long)]
    machine: Option<PathBuf>,
    /// SocketCAN interface (can0, vcan0); without it the built-in simulator runs on an
    /// in-process bus.
    #[arg(long)]
    can: Option<String>,
    /// Go over Modbus to a PLC that owns the axes: `--modbus HOST:PORT` (a PLC, or
    /// `probebridge sim --modbus`), or `--modbus` alone for the built-in simulated PLC on
    /// loopback. A machine whose [bus] kind is "modbus" needs no flag.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "", conflicts_with = "can")]
    modbus: Option<String>,
    /// Pace the built-in simulator in real time instead of a virtual clock.
    #[arg(long)]
    realtime: bool,
    /// iceoryx2 service prefix for contacts and estimator requests.
    #[arg(long, default_value = "probebridge")]
    service: String,
    /// Record the CAN traffic of the session in candump's log format.
    #[arg(long)]
    candump: Option<PathBuf>,
    /// Inject seeded faults between the master and the CAN bus (a demonstration of
    /// how it copes), e.g. `drop=0.01,duplicate=0.001,delay=0.001,reorder=0.001,seed=7`;
    /// `tx-`/`rx-` before a name sets one direction.
    #[arg(long, value_name = "SPEC", value_parser = hal::can::fault_injection::BusFaults::parse, conflicts_with = "modbus")]
    bus_faults: Option<hal::can::fault_injection::BusFaults>,
}

impl MachineArgs {
    fn options(&self) -> MachineOptions {
        MachineOptions {
            scenario: self.scenario.clone(),
            machine: self.machine.clone(),
            can: self.can.clone(),
            modbus: self.modbus.clone(),
            realtime: self.realtime,
            service: self.service.clone(),
            candump: self.candump.clone(),
            bus_faults: self.bus_faults.clone(),
            abort: None,
        }
    }

    /// The options of a command that moves the axes: a stop signal brakes them.
    fn moving_options(&self) -> Result<MachineOptions, String> {
        probebridge::stop_signal::install()?;
        Ok(MachineOptions {
            abort: Some(probebridge::stop_signal::flag()),
            ..self.options()
        })
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Move to a start point, probe along a direction, print the latched contact.
    Probe {
        #[command(flatten)]
        machine: MachineArgs,
        /// Start point X,Y,Z (mm, machine coordinates).
        #[arg(long, allow_hyphen_values = true)]
        start: String,
        /// Probing direction DX,DY,DZ (normalised).
        #[arg(long, allow_hyphen_values = true)]
        dir: String,
        /// Longest probing path, mm.
        #[arg(long)]
        dist: f64,
        /// Probing feed, mm/min.
        #[arg(long)]
        feed: f64,
        /// Also write the contact as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// The simulated machine with a calibration sphere: probe it, fit it in the
    /// estimator process.
    Demo {
        #[command(flatten)]
        machine: MachineArgs,
        /// Keep the demo's temporary folder (its 451 program, kinematics copy, protocol
        /// and the estimator's log) and say where; without it the folder is removed.
        #[arg(long)]
        keep: bool,
        /// Also print the estimator process's own lines and the drives' start-up detail.
        #[arg(long)]
        verbose: bool,
    },
    /// Run every measuring cycle of an NC program (.h) on the machine.
    Run {
        /// The NC program.
        program: PathBuf,
        #[command(flatten)]
        machine: MachineArgs,
        /// Folder for the protocols (default: protocols/ in the machine's state
        /// folder).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write the results as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Go on where a cycle asks for confirmation.
        #[arg(long)]
        yes: bool,
        /// Active kinematics file of the machine (cycles 450/451); default:
        /// <machine>.kinematics.toml in the machine's state folder.
        #[arg(long)]
        kinematics: Option<PathBuf>,
        /// The state directory (preset table, kinematics, probe table, protocols, one
        /// folder per machine); default: $XDG_STATE_HOME/probebridge, else
        /// ~/.local/state/probebridge.
        #[arg(long, value_name = "DIR")]
        state_dir: Option<PathBuf>,
        /// Record the run in this history: an SQLite file (as `serve` keeps it) or a
        /// PostgreSQL server's `postgres://` URL.
        #[arg(long, value_name = "FILE|URL")]
        history: Option<PathBuf>,
        /// Preset table of the machine (cycles 247, 451); default:
        /// <machine>.presets.toml in the machine's state folder.
        #[arg(long)]
        presets: Option<PathBuf>,
    },
    /// Parse and validate an NC program; nothing moves. Exit 0, or 2 with every error.
    Check(CheckArgs),
    /// Run the simulated drives of a scenario alone on a SocketCAN interface, or the
    /// simulated PLC on Modbus TCP (--modbus HOST:PORT) or RTU (--modbus-rtu DEVICE).
    Sim {
        #[arg(long)]
        scenario: Option<PathBuf>,
        #[arg(long, required_unless_present_any = ["modbus", "modbus_rtu"], conflicts_with_all = ["modbus", "modbus_rtu"])]
        can: Option<String>,
        /// Serve the simulated PLC's mailbox on Modbus TCP at HOST:PORT (port 0: any).
        #[arg(long, value_name = "ADDR", conflicts_with = "modbus_rtu")]
        modbus: Option<String>,
        /// Serve the simulated PLC's mailbox on Modbus RTU at this serial device.
        #[arg(long, value_name = "DEVICE")]
        modbus_rtu: Option<String>,
        /// Pace the simulated PLC in real time (default: moves run as fast as simulated).
        #[arg(long)]
        realtime: bool,
    },
    /// The estimator process: receives contacts over iceoryx2, fits, answers requests.
    Estimator(commands::estimator::EstimatorArgs),
    /// The gateway service: the machine up once, measurements on request of the PLC
    /// or HMI over a Modbus TCP face, readiness and watchdog for systemd.
    Serve {
        /// Gateway configuration (TOML).
        #[arg(long, default_value = probebridge::serve::config::DEFAULT_PATH)]
        config: PathBuf,
    },
    /// A line of the OPC UA face's users file (`NAME:argon2id hash`) for NAME, the
    /// password read from the first line of standard input.
    OpcuaUser {
        /// The user's name (letters, digits, _ - . @).
        name: String,
    },
    /// The OPC UA face's server certificate: its names and validity; `--renew`
    /// replaces it (and its key) by a new one, for the clients to trust.
    OpcuaCertificate {
        /// Gateway configuration (TOML).
        #[arg(long, default_value = probebridge::serve::config::DEFAULT_PATH)]
        config: PathBuf,
        /// Make a new certificate (restart `serve` to use it).
        #[arg(long)]
        renew: bool,
    },
    /// The recorded measurements of a gateway (its history file).
    History {
        /// The history file, or a PostgreSQL server's `postgres://` URL; default: the
        /// history of the gateway configuration.
        #[arg(long, value_name = "FILE|URL")]
        db: Option<PathBuf>,
        /// Gateway configuration naming the history file.
        #[arg(long, default_value = probebridge::serve::config::DEFAULT_PATH)]
        config: PathBuf,
        /// Only this machine.
        #[arg(long)]
        machine: Option<String>,
        /// Only runs started at or after this UTC date (YYYY-MM-DD or
        /// YYYY-MM-DDTHH:MM:SSZ).
        #[arg(long)]
        since: Option<String>,
        /// As JSON, with every result.
        #[arg(long)]
        json: bool,
        /// Write the trend page (451's errors and dispersion over time, SVG) to FILE;
        /// several machines: FILE is their index, each machine's page beside it
        /// (FILE-1.html, ...).
        #[arg(long, value_name = "FILE")]
        html: Option<PathBuf>,
        /// Mark a run whose identified position error or dispersion changed by more
        /// than this since the previous run, µm (default: the gateway configuration's
        /// `[history] alarm_um`, else 5).
        #[arg(long, value_name = "UM")]
        alarm_um: Option<f64>,
        /// The same for orientation errors, arcsec (default: `[history] alarm_arcsec`,
        /// else 10).
        #[arg(long, value_name = "ARCSEC")]
        alarm_arcsec: Option<f64>,
    },
    /// Benchmarks.
    #[command(subcommand)]
    Bench(BenchCmd),
    /// Writes the manual pages (roff, section 1: probebridge.1 and one per command) from
    /// these definitions into DIR; scripts/package ships them.
    #[command(hide = true)]
    Manpage { dir: PathBuf },
}

#[derive(Subcommand)]
enum BenchCmd {
    /// Latency from the drives' latch to the contact sample in the estimator process,
    /// with the bare iceoryx2 hop between the same processes as the floor.
    Trigger(commands::bench::trigger::BenchArgs),
    /// The machine time of the shipped examples: `check`'s prediction, `run`'s on the
    /// simulator's clock and the plan's lower bound, per cycle (docs/cycles.md).
    Cycles(commands::bench::cycles::CyclesBenchArgs),
}

/// `check`'s arguments.
#[derive(Args)]
struct CheckArgs {
    program: PathBuf,
    #[command(flatten)]
    machine: MachineArgs,
    /// Active kinematics file the program's cycle 451 would use; default:
    /// <machine>.kinematics.toml in the machine's state folder.
    #[arg(long)]
    kinematics: Option<PathBuf>,
    /// Preset table the program's cycle 247 is checked against; default:
    /// <machine>.presets.toml in the machine's state folder.
    #[arg(long)]
    presets: Option<PathBuf>,
    /// The state directory (see `run`); `check` only reads it.
    #[arg(long, value_name = "DIR")]
    state_dir: Option<PathBuf>,
    /// Print the result as JSON on stdout: `ok`, the errors, or each cycle's
    /// `predicted_machine_time_s` and `lower_bound_s` and the program's.
    #[arg(long)]
    json: bool,
}

impl CheckArgs {
    fn run(self) -> Result<u8, String> {
        commands::check::run(
            &self.program,
            &self.machine.options(),
            self.kinematics.as_deref(),
            self.presets.as_deref(),
            self.state_dir.as_deref(),
            self.json,
        )
    }
}

/// `manpage DIR`: probebridge.1 and a page per command, from the CLI's definitions.
fn man_pages(dir: &std::path::Path) -> Result<u8, String> {
    clap_mangen::generate_to(Cli::command(), dir)
        .map(|()| 0)
        .map_err(|e| format!("cannot write the manual pages to {}: {e}", dir.display()))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // iceoryx2 logs its defaults at warning level; keep the operator's terminal for
    // what matters unless IOX2_LOG_LEVEL asks for more.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let result: Result<u8, String> = match cli.command {
        Cmd::Probe {
            machine,
            start,
            dir,
            dist,
            feed,
            json,
        } => parse_vec3("--start", &start)
            .and_then(|start| {
                let dir = parse_vec3("--dir", &dir)?;
                commands::probe::run(&commands::probe::ProbeArgs {
                    machine: machine.moving_options()?,
                    start,
                    dir,
                    dist,
                    feed,
                    json,
                })
            })
            .map(|()| 0),
        Cmd::Run {
            program,
            machine,
            out,
            json,
            yes,
            kinematics,
            state_dir,
            history,
            presets,
        } => machine.moving_options().and_then(|machine| {
            commands::run::run(&commands::run::RunArgs {
                program,
                machine,
                out,
                json,
                yes,
                kinematics,
                history,
                presets,
                state_dir,
            })
        }),
        Cmd::Check(c) => c.run(),
        Cmd::Demo {
            machine,
            keep,
            verbose,
        } => machine
            .moving_options()
            .and_then(|m| commands::demo::run(&m, commands::demo::DemoOutput { keep, verbose }))
            .map(|()| 0),
        Cmd::Sim {
            scenario,
            can,
            modbus,
            modbus_rtu,
            realtime,
        } => match (can, modbus, modbus_rtu) {
            (Some(can), _, _) => commands::sim::run(scenario, &can),
            (None, Some(addr), _) => commands::sim::run_plc_tcp(scenario, &addr, realtime),
            (None, None, Some(dev)) => commands::sim::run_plc_rtu(scenario, &dev, realtime),
            (None, None, None) => Err("give --can, --modbus or --modbus-rtu".into()),
        }
        .map(|()| 0),
        Cmd::Estimator(args) => commands::estimator::run(args).map(|()| 0),
        Cmd::Bench(BenchCmd::Cycles(args)) => commands::bench::cycles::run(&args).map(|()| 0),
        Cmd::Bench(BenchCmd::Trigger(args)) if args.modbus => {
            commands::bench::modbus::run(&commands::bench::modbus::ModbusBenchArgs {
                triggers: args.triggers,
                warmup: args.warmup,
                plc_cycle_us: args.period_us.unwrap_or(250),
                poll_ms: args.poll_ms,
                json: args.json,
            })
            .map(|()| 0)
        }
        Cmd::History {
            db,
            config,
            machine,
            since,
            json,
            html,
            alarm_um,
            alarm_arcsec,
        } => commands::history::run(&commands::history::HistoryArgs {
            db,
            config,
            machine,
            since,
            json,
            html,
            alarm_um,
            alarm_arcsec,
        })
        .map(|()| 0),
        Cmd::Serve { config } => probebridge::serve::run(&config),
        Cmd::OpcuaUser { name } => commands::opcua_user::run(&name).map(|()| 0),
        Cmd::OpcuaCertificate { config, renew } => {
            commands::opcua_certificate::run(&config, renew).map(|()| 0)
        }
        Cmd::Bench(BenchCmd::Trigger(args)) => commands::bench::trigger::run(&args).map(|()| 0),
        Cmd::Manpage { dir } => man_pages(&dir),
    };
    // After a stop signal the session is closed (axes braked, drives disabled) and
    // the results written: exit as the signal says.
    let stopped_by = probebridge::stop_signal::exit_status();
    match result {
        Ok(code) => ExitCode::from(stopped_by.unwrap_or(code)),
        Err(e) if stopped_by.is_some() => {
            tell!("probebridge: {e}");
            ExitCode::from(stopped_by.unwrap_or(1))
        }
        Err(e) => {
            tell!("probebridge: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The docs' links, tree paths and command lines against this CLI (test only; beside
/// the integration tests, since it is one, but inside the binary to reach `Cli`).
#[cfg(test)]
#[path = "../tests/docs_check/mod.rs"]
mod docs_check;
