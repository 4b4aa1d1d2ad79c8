//! The OPC UA face of the gateway (`[opcua]`, off unless configured): the machine's
//! state, its results and its history to the factory's MES and SCADA, and methods to
//! start, abort and acknowledge by the PLC face's rules. Built on async-opcua's server
//! (pure-Rust crypto), on a tokio runtime of its own thread like the other faces. The
//! machine is a Machine Tools `MachineToolType` built from the companion
//! specifications' NodeSets ([`companion`], [`address_space`]).
//!
//! Security: endpoints Basic256Sha256 Sign and SignAndEncrypt (and `none` only where
//! configured); the server's certificate is made on first start in the state
//! directory and kept; client certificates are trusted by moving them from `rejected/`
//! to `trusted/`. Anonymous clients read; users of the users file (argon2id hashes)
//! call the methods.
//!
//! Robustness as the PLC face: a connection cap at the door ([`front`]), bounded
//! session, subscription and notification queues (a client that subscribes and never
//! publishes costs at most `max_queued_notifications` messages per subscription), and
//! a heartbeat the service loop watches: a face that stalls or ends ends the service.

pub mod address_space;
pub mod auth;
pub mod certificate;
pub mod companion;
pub mod config;
pub mod front;
pub mod gateway_types;
pub mod login_throttle;
pub mod methods;
pub mod users;
pub mod values;

use super::face_thread::{FaceHealth, FaceThread, Flavour, Heartbeat};
use super::gateway::Shared;
use opcua::crypto::SecurityPolicy;
use opcua::server::node_manager::memory::{simple_node_manager_imports, SimpleNodeManager};
use opcua::server::{ServerBuilder, ANONYMOUS_USER_TOKEN_ID};
use opcua::types::{BuildInfo, DateTime, MessageSecurityMode};
use std::net::SocketAddr;
use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How often the server looks at its subscriptions: a change reaches a subscriber
/// within about this plus the client's publishing interval.
const SUBSCRIPTION_TICK_MS: u64 = 10;
/// Fault injection for the service's supervision tests (never set in production):
/// `end` ends the face 1 s after start.
pub const FAULT_ENV: &str = "PROBEBRIDGE_FAULT_OPCUA_FACE";

/// The face's certificate files below the PKI folder (async-opcua's layout).
const OWN_CERT: &str = "own/cert.der";
const OWN_KEY: &str = "private/private.pem";

pub struct OpcuaFace {
    pub local_addr: SocketAddr,
    pub endpoint_url: String,
    pub certificate: PathBuf,
    thread: FaceThread,
}

/// What the face needs from the rest of the service once the machine is up.
pub struct Context<'a> {
    pub cfg: &'a super::config::GatewayConfig,
    pub shared: &'a Shared,
    pub machine: &'a str,
    /// How the machine is reached, for Monitoring/Bus.
    pub bus: String,
}

/// Where the state directory puts the face's files unless `[opcua]` says otherwise.
fn state_paths(section: &config::OpcuaSection) -> Result<(PathBuf, PathBuf), String> {
    let need_state = section.pki.is_none() || section.users.is_none();
    let state = if need_state {
        Some(crate::state_dir::state_dir(None)?.join("opcua"))
    } else {
        None
    };
    let pki = section
        .pki
        .clone()
        .or_else(|| state.as_ref().map(|s| s.join("pki")))
        .unwrap_or_default();
    let users = section
        .users
        .clone()
        .or_else(|| state.as_ref().map(|s| s.join("users")))
        .unwrap_or_default();
    Ok((pki, users))
}

/// Makes `dir` (and its parents), only for the service's user.
fn private_dir(dir: &Path) -> std::io::Result<()> {
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
}

/// The face as configured, checked and bound before the machine is opened (a port
/// in use, a users file others may read: said at once, nothing moved).
pub struct Prepared {
    section: config::OpcuaSection,
    securities: Vec<config::Security>,
    pki: PathBuf,
    users: users::Users,
    listener: std::net::TcpListener,
    local_addr: SocketAddr,
    bind: SocketAddr,
    host: String,
}

/// Checks `[opcua]` (none: `None`): the state folder, the users file, the port.
pub fn prepare(cfg: &super::config::GatewayConfig) -> Result<Option<Prepared>, String> {
    let Some(section) = &cfg.opcua else {
        return Ok(None);
    };
    let file = cfg.path.display();
    let bind = section
        .bind()
        .map_err(|(k, why)| format!("{file}: {k}: {why}"))?;
    let securities = section
        .securities()
        .map_err(|(k, why)| format!("{file}: {k}: {why}"))?;
    let (pki, users_path) = state_paths(section).map_err(|e| format!("{file}: opcua: {e}"))?;
    private_dir(&pki).map_err(|e| {
        format!(
            "{file}: opcua.pki: cannot make the folder {}: {e}",
            pki.display()
        )
    })?;
    let users = users::Users::load(&users_path).map_err(|e| format!("{file}: opcua.users: {e}"))?;
    if users.is_empty() {
        tracing::warn!(
            users = %users_path.display(),
            "OPC UA face: no users: the methods cannot be called (make the file with \
             `probebridge opcua-user NAME`)"
        );
    } else {
        tracing::info!(users = users.len(), file = %users_path.display(), "OPC UA face: users");
    }
    let listener = std::net::TcpListener::bind(bind)
        .and_then(|l| l.set_nonblocking(true).map(|()| l))
        .map_err(|e| format!("{file}: opcua.listen: cannot bind {bind}: {e}"))?;
    let local_addr = listener.local_addr().map_err(|e| e.to_string())?;
    Ok(Some(Prepared {
        host: section.advertised_host(bind),
        section: section.clone(),
        securities,
        pki,
        users,
        listener,
        local_addr,
        bind,
    }))
}

/// The certificate of `[opcua]` for `machine`: its files and what it is made of.
fn certificate_of(
    section: &config::OpcuaSection,
    pki: &Path,
    bind: SocketAddr,
    machine: &str,
) -> (certificate::Files, certificate::Identity) {
    let host = section.advertised_host(bind);
    (
        certificate::Files::new(pki, OWN_CERT, OWN_KEY),
        certificate::Identity::new(section, bind, &host, machine),
    )
}

/// `probebridge opcua-certificate`: says the server certificate's names and validity;
/// with `renew`, replaces it (and its key) by a new one first.
pub fn certificate_command(
    cfg: &super::config::GatewayConfig,
    machine: &str,
    renew: bool,
) -> Result<String, String> {
    let file = cfg.path.display();
    let section = cfg
        .opcua
        .as_ref()
        .ok_or_else(|| format!("{file}: no [opcua] section: the OPC UA face is off"))?;
    let bind = section
        .bind()
        .map_err(|(k, why)| format!("{file}: {k}: {why}"))?;
    let (pki, _) = state_paths(section).map_err(|e| format!("{file}: opcua: {e}"))?;
    private_dir(&pki).map_err(|e| format!("{file}: opcua.pki: {}: {e}", pki.display()))?;
    let (files, who) = certificate_of(section, &pki, bind, machine);
    let cert = match certificate::read(&files)? {
        Some(c) if !renew => c,
        _ => {
            certificate::make(&files, &who)?;
            certificate::read(&files)?.ok_or("the new certificate is gone")?
        }
    };
    let v = certificate::Validity::of(&cert, std::time::SystemTime::now())?;
    Ok(format!(
        "{}: {}, valid until {} ({} days left), thumbprint {}",
        files.cert.display(),
        cert.subject_name(),
        v.not_after,
        v.left_s.div_euclid(24 * 3600),
        cert.thumbprint().as_hex_string()
    ))
}

impl Prepared {
    /// The server certificate, before the machine opens: made if there is none, an
    /// expired one refused, one close to expiry a warning.
    pub fn check_certificate(
        &self,
        cfg: &super::config::GatewayConfig,
        machine: &str,
    ) -> Result<(), String> {
        let (files, who) = certificate_of(&self.section, &self.pki, self.bind, machine);
        certificate::check_at_start(&files, &who)
            .map_err(|e| format!("{}: opcua: {e}", cfg.path.display()))
    }

    /// Starts the face (the machine is up) and says its endpoint on stdout.
    pub fn start(self, ctx: &Context) -> Result<OpcuaFace, String> {
        let file = ctx.cfg.path.display();
        let section = &self.section;
        let endpoint_url = format!("opc.tcp://{}:{}/", self.host, self.local_addr.port());
        let setup = Setup {
            server: ServerArgs {
                section: section.clone(),
                securities: self.securities.clone(),
                machine: ctx.machine.to_string(),
                host: self.host.clone(),
                port: self.local_addr.port(),
                pki: self.pki.clone(),
                auth: auth::Auth::new(self.users, section.anonymous, section.may_start),
            },
            shared: ctx.shared.clone(),
            identity: address_space::Identity {
                machine: ctx.machine.to_string(),
                manufacturer: section.manufacturer.clone(),
                manufacturer_uri: section.manufacturer_uri.clone(),
                model: section.model.clone(),
                serial_number: section.serial_number.clone(),
                bus: ctx.bus.clone(),
                application_uri: certificate::application_uri(&self.host, ctx.machine),
            },
            history: ctx.cfg.history(),
            last_runs: section.last_runs,
            door: front::Limits {
                max_connections: section.max_connections,
                idle_timeout: Duration::from_millis(section.session_timeout_ms),
            },
            listener: self.listener,
        };
        let face = OpcuaFace::start(setup, &self.pki, self.local_addr, endpoint_url)
            .map_err(|e| format!("{file}: opcua: {e}"))?;
        tracing::info!(
            endpoint = %face.endpoint_url,
            certificate = %face.certificate.display(),
            "OPC UA face ready"
        );
        crate::say!("probebridge serve: OPC UA face on {}", face.endpoint_url);
        Ok(face)
    }
}

fn server_builder(
    imports: Vec<Box<dyn opcua::nodes::NodeSetImport>>,
    section: &config::OpcuaSection,
    securities: &[config::Security],
    machine: &str,
    host: &str,
    port: u16,
    pki: &Path,
) -> ServerBuilder {
    let version = env!("CARGO_PKG_VERSION");
    let mut b = ServerBuilder::new()
        .application_name(format!("probebridge {machine}"))
        .application_uri(certificate::application_uri(host, machine))
        .product_uri("urn:probebridge")
        .build_info(BuildInfo {
            product_uri: "urn:probebridge".into(),
            manufacturer_name: "probebridge".into(),
            product_name: "probebridge gateway".into(),
            software_version: version.into(),
            build_number: version.into(),
            build_date: DateTime::now(),
        })
        .with_node_manager(simple_node_manager_imports(imports, "probebridge"))
        // Made by the gateway (certificate.rs) before the server starts.
        .create_sample_keypair(false)
        .certificate_path(OWN_CERT)
        .private_key_path(OWN_KEY)
        .pki_dir(pki)
        .trust_client_certs(section.trust_client_certs)
        .host(host)
        .port(port)
        // Full URLs: a client that finds the server uses them as they are.
        .discovery_urls(vec![format!("opc.tcp://{host}:{port}/")])
        .max_sessions(section.max_sessions)
        .max_session_timeout_ms(section.session_timeout_ms)
        .subscription_poll_interval_ms(SUBSCRIPTION_TICK_MS)
        .diagnostics_enabled(false);
    {
        let s = &mut b.limits_mut().subscriptions;
        s.max_subscriptions_per_session = section.max_subscriptions_per_session;
        s.max_monitored_items_per_sub = section.max_monitored_items_per_subscription;
        s.max_queued_notifications = section.max_queued_notifications;
        s.min_publishing_interval_ms = SUBSCRIPTION_TICK_MS as f64;
        s.min_sampling_interval_ms = SUBSCRIPTION_TICK_MS as f64;
    }
    let tokens: &[&str] = &[ANONYMOUS_USER_TOKEN_ID];
    for sec in securities {
        let (id, policy, mode) = match sec {
            config::Security::None => ("none", SecurityPolicy::None, MessageSecurityMode::None),
            config::Security::Sign => (
                config::SIGN,
                SecurityPolicy::Basic256Sha256,
                MessageSecurityMode::Sign,
            ),
            config::Security::SignAndEncrypt => (
                config::SIGN_ENCRYPT,
                SecurityPolicy::Basic256Sha256,
                MessageSecurityMode::SignAndEncrypt,
            ),
        };
        b = b.add_endpoint(id, ("/", policy, mode, tokens));
    }
    b
}

/// What the server is built from (on the face's thread: the builder is not Send).
struct ServerArgs {
    section: config::OpcuaSection,
    securities: Vec<config::Security>,
    machine: String,
    host: String,
    port: u16,
    pki: PathBuf,
    auth: auth::Auth,
}

/// What the face's thread is given.
struct Setup {
    server: ServerArgs,
    shared: Shared,
    identity: address_space::Identity,
    history: Option<crate::history::HistoryTarget>,
    last_runs: usize,
    door: front::Limits,
    listener: std::net::TcpListener,
}

impl OpcuaFace {
    fn start(
        setup: Setup,
        pki: &Path,
        local_addr: SocketAddr,
        endpoint_url: String,
    ) -> Result<Self, String> {
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let fault = std::env::var(FAULT_ENV).unwrap_or_default();
        let thread = FaceThread::spawn(
            "probebridge-opcua-face",
            "OPC UA face",
            Flavour::MultiThread,
            move |heartbeat, stop| serve(setup, ready_tx, stop, heartbeat, fault),
        )
        .map_err(|e| e.to_string())?;
        let certificate = pki.join(OWN_CERT);
        let mut face = Self {
            local_addr,
            endpoint_url,
            certificate: certificate.clone(),
            thread,
        };
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => {
                let why = match face.health() {
                    FaceHealth::Ended(why) => why,
                    _ => "it ended while starting".into(),
                };
                return Err(why);
            }
        }
        // The certificate is made on first start and kept; its key is the service's.
        let key = pki.join(OWN_KEY);
        if !certificate.is_file() || !key.is_file() {
            return Err(format!(
                "opcua.pki: no certificate {} with its key {} (none could be made: see the \
                 lines above)",
                certificate.display(),
                key.display()
            ));
        }
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600))
            .map_err(|e| format!("opcua.pki: {}: {e}", key.display()))?;
        Ok(face)
    }

    pub fn health(&mut self) -> FaceHealth {
        self.thread.health()
    }
}

/// The face's runtime: builds the server and its nodes, says on `ready` whether it
/// came up, then serves until `stop`.
async fn serve(
    setup: Setup,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
    stop: tokio::sync::oneshot::Receiver<()>,
    heartbeat: Heartbeat,
    fault: String,
) -> Result<(), String> {
    let up = bring_up(setup).await;
    let (server_task, front_task, publisher_task, handle) = match up {
        Ok(parts) => parts,
        Err(e) => {
            let _ = ready.send(Err(e.clone()));
            return Err(e);
        }
    };
    // Alive from here: the bring-up (seconds on a slow gateway) is not a stall.
    heartbeat.beat();
    let ticker = tokio::spawn(heartbeat.run());
    let _ = ready.send(Ok(()));
    let faulty = async {
        if fault.is_empty() {
            std::future::pending::<()>().await;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        tracing::warn!("{FAULT_ENV}={fault}: injecting the fault");
    };
    let result = tokio::select! {
        _ = stop => Ok(()),
        r = server_task => Err(format!("the OPC UA server ended: {}", match r {
            Ok(Ok(())) => "it returned".to_string(),
            Ok(Err(e)) => e,
            Err(e) => e.to_string(),
        })),
        r = front_task => Err(format!("its door ended: {r:?}")),
        r = publisher_task => Err(format!("its values stopped: {r:?}")),
        () = faulty => Err(format!("ended by {FAULT_ENV}={fault}")),
    };
    ticker.abort();
    handle.cancel();
    result
}

type Parts = (
    tokio::task::JoinHandle<Result<(), String>>,
    tokio::task::JoinHandle<()>,
    tokio::task::JoinHandle<()>,
    opcua::server::ServerHandle,
);

async fn bring_up(setup: Setup) -> Result<Parts, String> {
    let public_port = setup
        .listener
        .local_addr()
        .map_err(|e| e.to_string())?
        .port();
    let a = setup.server;
    let throttle = a.auth.throttle();
    let certificate = certificate::Files::new(&a.pki, OWN_CERT, OWN_KEY);
    let imports = companion::imports(address_space::NAMESPACE)?;
    let (server, handle) = server_builder(
        imports,
        &a.section,
        &a.securities,
        &a.machine,
        &a.host,
        a.port,
        &a.pki,
    )
    .with_authenticator(Arc::new(a.auth))
    .build()
    .map_err(|e| format!("the OPC UA server: {e}"))?;
    let manager = handle
        .node_managers()
        .get_of_type::<SimpleNodeManager>()
        .ok_or("the OPC UA server has no node manager of the machine")?;
    let index = |uri: &str| {
        handle
            .get_namespace_index(uri)
            .ok_or_else(|| format!("the OPC UA server has no namespace {uri}"))
    };
    let namespaces = companion::Namespaces {
        own: index(address_space::NAMESPACE)?,
        di: index(companion::DI)?,
        machinery: index(companion::MACHINERY)?,
        machine_tool: index(companion::MACHINE_TOOL)?,
    };
    let ns = namespaces.own;
    let nodes = {
        let mut space = manager.address_space().write();
        address_space::build(&mut space, namespaces, &setup.identity, setup.last_runs)
    };
    methods::register(&manager, ns, &setup.shared);
    let internal = tokio::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
        .await
        .map_err(|e| format!("cannot bind the server's loopback port: {e}"))?;
    let internal_addr = internal.local_addr().map_err(|e| e.to_string())?;
    let info = handle.info().clone();
    let server_task = tokio::spawn(server.run_with(internal));
    // The server takes its listener's port for the endpoints it describes; clients
    // must be told the door's. It stores it once, before its first accept.
    let deadline = Instant::now() + Duration::from_secs(10);
    while info.port.load(Ordering::Acquire) != internal_addr.port() {
        if Instant::now() > deadline || server_task.is_finished() {
            return Err("the OPC UA server did not start".into());
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    info.port.store(public_port, Ordering::Release);
    let listener = tokio::net::TcpListener::from_std(setup.listener)
        .map_err(|e| format!("cannot listen: {e}"))?;
    let front_task = tokio::spawn(front::serve(listener, internal_addr, setup.door));
    let publisher = values::Publisher::new(
        nodes,
        manager,
        handle.subscriptions().clone(),
        setup.history,
        setup.identity.machine.clone(),
    );
    let publisher_task = tokio::spawn(publisher.run(setup.shared.clone()));
    tokio::spawn(async move {
        let every = certificate::CHECK_EVERY;
        let mut daily = tokio::time::interval_at(tokio::time::Instant::now() + every, every);
        loop {
            daily.tick().await;
            if let Some(w) = certificate::check_now(&certificate) {
                tracing::warn!("{w}");
            }
        }
    });
    // The failed logins' summary also when no further failure comes to say it.
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(login_throttle::SUMMARY_EVERY / 6);
        loop {
            tick.tick().await;
            if let Some(line) = throttle.summary(Instant::now()) {
                tracing::warn!("{line}");
            }
        }
    });
    Ok((server_task, front_task, publisher_task, handle))
}
