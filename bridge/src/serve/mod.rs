//! `probebridge serve`: the gateway service. It brings the machine up once, keeps the
//! estimator process running, and runs measurements the PLC or HMI asks for over its
//! Modbus TCP face, one at a time. SIGTERM, SIGINT or SIGHUP abort a running
//! measurement (the axes stop, the run ends "aborted") and the service exits 0; a
//! second one during a slow stop exits at once (128 + signal), as `run` does. SIGUSR1
//! restarts it between measurements (exit 75, see [`RESTART_EXIT`]).

pub mod config;
pub mod face_log;
pub mod face_thread;
pub mod gateway;
pub mod handshake;
pub mod machine_link;
pub mod machine_thread;
pub mod measurement;
pub mod modbus_face;
pub mod opcua;
pub mod outcome;
pub mod ownership;
pub mod peer_allow;
pub mod plc_registers;
pub mod prepare;
pub mod register_map;
pub mod results;
pub mod sd_notify;
pub mod service;
pub mod tcp_keepalive;
pub mod web_face;

use config::GatewayConfig;
use face_thread::FaceHealth;
use gateway::{lock, Gateway};
use hal::AbortFlag;
use handshake::Handshake;
use measurement::State;
use outcome::AbortReason;
use register_map::RegisterMap;
use service::{Service, ToMachine};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// The signal that asked the service to stop (0: none).
static STOP_SIGNAL: AtomicI32 = AtomicI32::new(0);
/// The gateway's stop request, for the handler: a second signal brakes before it exits.
static ABORT: OnceLock<AbortFlag> = OnceLock::new();

/// The signals that stop the service: SIGHUP too (a closed terminal, a stray
/// `kill -HUP`), so it never ends with the axes moving and the run left `running`.
const SIGNALS: [libc::c_int; 3] = [libc::SIGTERM, libc::SIGINT, libc::SIGHUP];

/// SIGUSR1: restart between measurements (a package upgrade asks for it). The service
/// ends with [`RESTART_EXIT`] once no measurement runs or is being prepared; the unit's
/// `RestartForceExitStatus=` starts it again, on the upgraded binary.
static RESTART_WHEN_IDLE: AtomicBool = AtomicBool::new(false);

/// The exit status of a restart between measurements (EX_TEMPFAIL).
pub const RESTART_EXIT: u8 = 75;

extern "C" fn on_restart_signal(_: libc::c_int) {
    RESTART_WHEN_IDLE.store(true, Ordering::Release);
}

extern "C" fn on_signal(sig: libc::c_int) {
    if STOP_SIGNAL
        .compare_exchange(0, sig, Ordering::AcqRel, Ordering::Acquire)
        .is_err()
    {
        // The second signal during a slow stop: someone insists. The first one has
        // asked the machine to brake; raise that again (in case the service loop has
        // not seen the first yet: an atomic store; OnceLock::get is an atomic load
        // once set) and exit now.
        if let Some(flag) = ABORT.get() {
            flag.raise();
        }
        // SAFETY: _exit is async-signal-safe.
        unsafe { libc::_exit(128 + sig) };
    }
}

fn install_signal_handlers() {
    let handlers = SIGNALS
        .map(|sig| (sig, on_signal as extern "C" fn(libc::c_int)))
        .into_iter()
        .chain([(
            libc::SIGUSR1,
            on_restart_signal as extern "C" fn(libc::c_int),
        )]);
    for (sig, handler) in handlers {
        // SAFETY: the handlers only touch atomics and call _exit (async-signal-safe).
        unsafe {
            let mut act: libc::sigaction = std::mem::zeroed();
            act.sa_sigaction = handler as usize;
            libc::sigemptyset(&mut act.sa_mask);
            libc::sigaction(sig, &act, std::ptr::null_mut());
        }
    }
}

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        libc::SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// `PROBEBRIDGE_LOG=debug` shows each PLC connection (default: info).
pub const LOG_ENV: &str = "PROBEBRIDGE_LOG";

fn init_logging() {
    let level = match std::env::var(LOG_ENV).as_deref() {
        Ok("debug") => tracing::Level::DEBUG,
        Ok("trace") => tracing::Level::TRACE,
        Ok("warn") => tracing::Level::WARN,
        Ok("error") => tracing::Level::ERROR,
        _ => tracing::Level::INFO,
    };
    // The OPC UA stack logs each connection and each dropped notification of a client
    // that does not publish: only its errors, unless debugging.
    let stack = if level >= tracing::Level::DEBUG {
        level
    } else {
        tracing::Level::ERROR
    };
    let targets = [
        "opcua_server",
        "opcua_core",
        "opcua_crypto",
        "opcua_types",
        "opcua_nodes",
    ]
    .into_iter()
    .fold(
        tracing_subscriber::filter::Targets::new().with_default(level),
        |t, name| t.with_target(name, stack),
    );
    // The journal stamps every line itself: no time, no colours, level and message.
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .without_time()
        .with_target(false)
        .with_max_level(level)
        .finish()
        .with(targets)
        .with(opcua::login_throttle::StackLoginLines)
        .try_init();
}

const TICK: Duration = Duration::from_millis(50);
/// A PLC face stalled this long ends the service (the watchdog is no longer fed from
/// the moment the stall is seen).
const FACE_DEAD: Duration = Duration::from_secs(5);

/// Runs the service until SIGTERM, SIGINT or SIGHUP (exit status 0 after a clean stop),
/// or, after SIGUSR1, until no measurement runs ([`RESTART_EXIT`]).
pub fn run(config_path: &Path) -> Result<u8, String> {
    let mut cfg = GatewayConfig::load(config_path).map_err(|e| e.to_string())?;
    init_logging();
    install_signal_handlers();
    let listen = cfg.listen().map_err(|e| e.to_string())?;
    let order = cfg.word_order().map_err(|e| e.to_string())?;
    let face_opts = modbus_face::FaceOptions {
        max_connections: cfg.plc.max_connections as usize,
        max_per_peer: cfg.per_peer_cap() as usize,
        silence: cfg.owner_timeout(),
        allow: cfg.allow().map_err(|e| e.to_string())?,
    };
    // The PLC face's port before the machine: a port in use is found at once, not
    // after a CANopen start-up that Restart= would repeat every 2 s.
    let listener = modbus_face::bind(listen).map_err(|e| {
        format!(
            "{}: plc.listen: cannot bind {listen}: {e}",
            config_path.display()
        )
    })?;
    // The OPC UA face's files and port too: found wrong before the machine moves.
    let opcua = opcua::prepare(&cfg)?;
    let (machine_cfg, scenario) =
        crate::session::resolve_machine(&cfg.machine_options()).map_err(|e| e.to_string())?;
    if let Some(o) = &opcua {
        o.check_certificate(&cfg, &machine_cfg.name)?;
    }
    let cycles = machine_state(&mut cfg, &machine_cfg, scenario.as_ref())?;
    let notifier = sd_notify::Notifier::from_env();
    notifier.notify("STATUS=bringing the machine up");

    let (jobs_tx, jobs_rx) = std::sync::mpsc::channel::<ToMachine>();
    let mut service = Service::new(jobs_tx.clone());
    let history = open_history(&cfg, &cycles)?;
    if let Some(h) = &history {
        service.set_history(h.clone());
    }
    let _ = ABORT.set(service.abort_flag());
    let plc = plc_registers::PlcRegisters::new(
        RegisterMap::new(order, cfg.plc.int_scale),
        Handshake::new(cfg.heartbeat_timeout(), Instant::now()),
        ownership::Ownership::new(cfg.owner_timeout()),
    );
    let shared = Arc::new(Mutex::new(Gateway::new(service, plc)));
    let (machine, ready_rx) = machine_thread::spawn(
        cfg.clone(),
        cycles.clone(),
        shared.clone(),
        jobs_rx,
        history.clone(),
    )?;
    let notes = match ready_rx.recv() {
        Ok(Ok(notes)) => notes,
        Ok(Err(e)) => {
            let _ = machine.join();
            return Err(e);
        }
        Err(_) => return Err("the machine thread ended while starting".into()),
    };
    for n in &notes {
        tracing::info!("{n}");
    }
    let mut face = modbus_face::PlcFace::start(shared.clone(), listener, face_opts)
        .map_err(|e| format!("PLC face on {listen}: {e}"))?;
    lock(&shared).service.set_machine_ok(true);
    tracing::info!(listen = %face.local_addr, machine = %machine_cfg.name, "gateway ready");
    // Tests and scripts read the bound address (port 0 takes any) from this line.
    crate::say!("probebridge serve: listening on {}", face.local_addr);
    let web = web_face::start_configured(&cfg, &shared, &machine_cfg.name)?;
    let mut opcua = match opcua {
        Some(o) => Some(o.start(&opcua::Context {
            cfg: &cfg,
            shared: &shared,
            machine: &machine_cfg.name,
            bus: bus_name(&cfg),
        })?),
        None => None,
    };
    let _ = std::io::stdout().flush();
    notifier.notify(&format!(
        "READY=1\nSTATUS=idle, PLC face on {}",
        face.local_addr
    ));

    let end = supervise(&shared, &notifier, &mut face, opcua.as_mut());
    end.log();
    notifier.notify("STOPPING=1\nSTATUS=stopping");
    {
        let mut gateway = lock(&shared);
        let service = &mut gateway.service;
        service.set_machine_ok(false);
        service.request_abort(AbortReason::Shutdown);
    }
    let _ = jobs_tx.send(ToMachine::Quit);
    let _ = machine.join();
    // A face that stalled (its death, or during the stop) is left behind by its drop.
    drop(face);
    drop(opcua);
    if let Some(h) = &history {
        h.stop();
    }
    drop(web);
    tracing::info!(state = lock(&shared).service.state().name(), "stopped");
    match end {
        End::Signal(_) => Ok(0),
        End::Restart => Ok(RESTART_EXIT),
        End::FaceDied(name, why) => Err(format!("the {name} is dead: {why}")),
    }
}

/// How the machine is reached, in words (the OPC UA face's Monitoring/Bus).
fn bus_name(cfg: &GatewayConfig) -> String {
    let m = &cfg.machine;
    match (&m.can, &m.modbus, &m.scenario) {
        (Some(can), _, _) => format!("CANopen on {can}"),
        (None, Some(modbus), _) => format!("Modbus {modbus}"),
        (None, None, Some(_)) => "simulator".into(),
        (None, None, None) => "CANopen".into(),
    }
}

/// The machine's state (preset table, kinematics, protocols) in the unit's
/// StateDirectory, seeded from the shipped configuration, as the CLI keeps it; the
/// cycles' configuration with that preset table.
fn machine_state(
    cfg: &mut GatewayConfig,
    machine_cfg: &hal::config::MachineConfig,
    scenario: Option<&sim::scenario::Scenario>,
) -> Result<cycles::CyclesConfig, String> {
    let files = crate::machine_state::machine_files(
        machine_cfg,
        None,
        None,
        cfg.machine.kinematics.as_deref(),
        true,
    )?;
    for n in &files.notes {
        tracing::info!("state: {n}");
    }
    cfg.machine.kinematics = Some(files.kinematics.clone());
    if cfg.programs.out.is_none() {
        cfg.programs.out = Some(files.protocols_dir());
    }
    let mut cycles_cfg =
        crate::session::cycles_config_with_presets(machine_cfg, scenario, Some(&files.presets))
            .map_err(|e| e.to_string())?;
    // The probes' calibration rows of the state, never the shipped folder's.
    cycles_cfg
        .use_calibrations(&files.probes)
        .map_err(|e| e.to_string())?;
    Ok(cycles_cfg)
}

/// The history of the gateway, opened before the machine (a history that is down is
/// opened again in the background; starts are refused meanwhile).
fn open_history(
    cfg: &GatewayConfig,
    cycles: &cycles::CyclesConfig,
) -> Result<Option<crate::history::recorder::Recorder>, String> {
    let Some(target) = cfg.history() else {
        return Ok(None);
    };
    let spool = cfg.spool_path();
    if let Some(folder) = spool.parent() {
        std::fs::create_dir_all(folder).map_err(|e| {
            format!(
                "{}: history.spool: cannot make the folder {}: {e}",
                cfg.path.display(),
                folder.display()
            )
        })?;
    }
    let r = crate::history::recorder::Recorder::start(
        target,
        cfg.history_timeouts(),
        &spool,
        &cycles.machine.name,
    )
    .map_err(|e| format!("{}: history.spool: {e}", cfg.path.display()))?;
    tracing::info!(spool = %spool.display(), "history spool");
    Ok(Some(r))
}

/// Why the service loop ended.
enum End {
    Signal(i32),
    /// SIGUSR1, and no measurement runs: starts are refused from here on.
    Restart,
    /// A face (its name) ended or stalled: the service must not live on deaf.
    FaceDied(&'static str, String),
}

impl End {
    fn log(&self) {
        match self {
            End::Signal(signal) => tracing::info!(
                signal,
                "stopping on {}: aborting a running measurement, closing the machine",
                signal_name(*signal)
            ),
            End::Restart => tracing::info!(
                "restarting as asked (SIGUSR1): no measurement runs, starts are refused"
            ),
            End::FaceDied(name, why) => tracing::error!(
                "the {name} is dead ({why}): stopping, for systemd to restart the service"
            ),
        }
    }
}

/// The service loop: ticks the handshake, keeps systemd's watchdog fed while the
/// faces serve, says the state in STATUS. Returns why the service ends.
fn supervise(
    shared: &gateway::Shared,
    notifier: &sd_notify::Notifier,
    face: &mut modbus_face::PlcFace,
    mut opcua: Option<&mut opcua::OpcuaFace>,
) -> End {
    let watchdog = sd_notify::Notifier::watchdog_interval();
    let mut last_watchdog = Instant::now();
    let mut last = (State::Idle, true);
    let mut stall_said = [false; 2];
    let mut restart_said = false;
    loop {
        let sig = STOP_SIGNAL.load(Ordering::Acquire);
        if sig != 0 {
            return End::Signal(sig);
        }
        let healths = [
            ("PLC face", Some(face.health())),
            ("OPC UA face", opcua.as_mut().map(|f| f.health())),
        ];
        let mut face_ok = true;
        for ((name, health), said) in healths.into_iter().zip(stall_said.iter_mut()) {
            match health {
                None | Some(FaceHealth::Serving) => *said = false,
                Some(FaceHealth::Stalled(d)) if d >= FACE_DEAD => {
                    return End::FaceDied(name, format!("it has not run for {} ms", d.as_millis()))
                }
                Some(FaceHealth::Stalled(d)) => {
                    if !*said {
                        tracing::error!(
                            "the {name} has not run for {} ms: no longer feeding the watchdog",
                            d.as_millis()
                        );
                        notifier.notify(&format!("STATUS={name} not answering"));
                        *said = true;
                    }
                    face_ok = false;
                }
                Some(FaceHealth::Ended(why)) => return End::FaceDied(name, why),
            }
        }
        let now = Instant::now();
        let (state, machine_ok) = {
            let mut gateway = lock(shared);
            gateway.tick(now);
            let service = &mut gateway.service;
            // Checked and refused under one lock: no start slips in between.
            if RESTART_WHEN_IDLE.load(Ordering::Acquire) {
                if service.between_measurements() {
                    service.set_machine_ok(false);
                    return End::Restart;
                }
                if !restart_said {
                    tracing::info!("restart asked (SIGUSR1): after the running measurement");
                    notifier.notify("STATUS=busy, restarting after this measurement");
                    restart_said = true;
                }
            }
            (service.state(), service.machine_ok())
        };
        if (state, machine_ok) != last {
            let machine = if machine_ok {
                ""
            } else {
                ", machine not ok: opening it again"
            };
            notifier.notify(&format!("STATUS={}{machine}", state.name()));
            last = (state, machine_ok);
        }
        if let Some(w) = watchdog.filter(|_| face_ok) {
            if now.duration_since(last_watchdog) >= w {
                notifier.notify("WATCHDOG=1");
                last_watchdog = now;
            }
        }
        std::thread::sleep(TICK);
    }
}
