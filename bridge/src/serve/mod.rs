//! `probebridge serve`: the gateway service. It brings the machine up once, keeps the
//! estimator process running, and runs measurements the PLC or HMI asks for over its
//! Modbus TCP face, one at a time. SIGTERM/SIGINT abort a running measurement (the
//! axes stop, the run ends "aborted") and the service exits 0.

pub mod config;
pub mod gateway;
pub mod handshake;
pub mod machine_link;
pub mod machine_thread;
pub mod modbus_face;
pub mod register_map;
pub mod sd_notify;

use config::GatewayConfig;
use gateway::{lock, Core, ToMachine};
use handshake::{AbortReason, Handshake, State};
use register_map::RegisterMap;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The signal that asked the service to stop (0: none).
static STOP_SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(sig: libc::c_int) {
    STOP_SIGNAL.store(sig, Ordering::Release);
}

fn install_signal_handlers() {
    for sig in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: the handler only stores into an atomic (async-signal-safe).
        unsafe {
            let mut act: libc::sigaction = std::mem::zeroed();
            act.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut act.sa_mask);
            libc::sigaction(sig, &act, std::ptr::null_mut());
        }
    }
}

fn init_logging() {
    // The journal stamps every line itself: no time, no colours, level and message.
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .without_time()
        .with_target(false)
        .with_max_level(tracing::Level::INFO)
        .try_init();
}

const TICK: Duration = Duration::from_millis(50);

/// Runs the service until SIGTERM/SIGINT. Exit status 0 after a clean stop.
pub fn run(config_path: &Path) -> Result<u8, String> {
    let mut cfg = GatewayConfig::load(config_path).map_err(|e| e.to_string())?;
    init_logging();
    install_signal_handlers();
    let listen = cfg.listen().map_err(|e| e.to_string())?;
    let order = cfg.word_order().map_err(|e| e.to_string())?;
    let (machine_cfg, scenario) =
        crate::session::resolve_machine(&cfg.machine_options()).map_err(|e| e.to_string())?;
    // The machine's state (preset table, kinematics, protocols) in the unit's
    // StateDirectory, seeded from the shipped configuration, as the CLI keeps it.
    let files = crate::machine_state::machine_files(
        &machine_cfg,
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
    let cycles = crate::session::cycles_config_with_presets(
        &machine_cfg,
        scenario.as_ref(),
        Some(&files.presets),
    )
    .map_err(|e| e.to_string())?;
    let notifier = sd_notify::Notifier::from_env();
    notifier.notify("STATUS=bringing the machine up");

    let (jobs_tx, jobs_rx) = std::sync::mpsc::channel::<ToMachine>();
    let core = Core::new(
        RegisterMap::new(order, cfg.plc.int_scale),
        Handshake::new(cfg.heartbeat_timeout(), Instant::now()),
        cfg.programs.folder.clone(),
        cycles.clone(),
        jobs_tx.clone(),
    );
    let shared = Arc::new(Mutex::new(core));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let machine = {
        let (cfg, cycles, shared) = (cfg.clone(), cycles.clone(), shared.clone());
        std::thread::Builder::new()
            .name("probebridge-machine".into())
            .spawn(move || machine_thread::run(&cfg, &cycles, &shared, &jobs_rx, &ready_tx))
            .map_err(|e| e.to_string())?
    };
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
    let face = modbus_face::PlcFace::start(shared.clone(), listen).map_err(|e| {
        format!(
            "{}: plc.listen: cannot bind {listen}: {e}",
            config_path.display()
        )
    })?;
    lock(&shared).set_machine_ok(true);
    tracing::info!(listen = %face.local_addr, machine = %machine_cfg.name, "gateway ready");
    // Tests and scripts read the bound address (port 0 takes any) from this line.
    crate::say!("probebridge serve: listening on {}", face.local_addr);
    let _ = std::io::stdout().flush();
    notifier.notify(&format!(
        "READY=1\nSTATUS=idle, PLC face on {}",
        face.local_addr
    ));

    let signal = supervise(&shared, &notifier);
    tracing::info!(signal, "stopping");
    notifier.notify("STOPPING=1\nSTATUS=stopping");
    {
        let mut core = lock(&shared);
        core.set_machine_ok(false);
        core.request_abort(AbortReason::Shutdown);
    }
    let _ = jobs_tx.send(ToMachine::Quit);
    let _ = machine.join();
    drop(face);
    tracing::info!(state = lock(&shared).state().name(), "stopped");
    Ok(0)
}

/// The service loop: ticks the handshake, keeps systemd's watchdog fed, says the state
/// in STATUS. Returns the signal that ends the service.
fn supervise(shared: &gateway::Shared, notifier: &sd_notify::Notifier) -> i32 {
    let watchdog = sd_notify::Notifier::watchdog_interval();
    let mut last_watchdog = Instant::now();
    let mut last = (State::Idle, true);
    loop {
        let sig = STOP_SIGNAL.load(Ordering::Acquire);
        if sig != 0 {
            return sig;
        }
        let now = Instant::now();
        let (state, machine_ok) = {
            let mut core = lock(shared);
            core.tick(now);
            (core.state(), core.machine_ok())
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
        if let Some(w) = watchdog {
            if now.duration_since(last_watchdog) >= w {
                notifier.notify("WATCHDOG=1");
                last_watchdog = now;
            }
        }
        std::thread::sleep(TICK);
    }
}
