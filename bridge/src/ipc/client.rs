//! The bridge's side of the request service: ask the estimator, wait for its reply.

use core::sync::atomic::{AtomicU64, Ordering};
use core::time::Duration;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::Instant;

use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;

use super::process_watch::ProcessWatch;
use super::{
    create_node, listener, notifier, open_event_service, open_request_service,
    remove_stale_resources, EstimatorReply, EstimatorRequest, IpcError, ReplyStatus, RequestKind,
    ServiceNames, SphereResult, Svc,
};

/// Client of the estimator's `<prefix>/requests` service.
pub struct EstimatorClient {
    // Field order = drop order: ports before the node.
    client: Client<Svc, EstimatorRequest, (), EstimatorReply, ()>,
    request_notifier: Notifier<Svc>,
    result_listener: Listener<Svc>,
    next_request_id: AtomicU64,
    names: ServiceNames,
    /// The process that answered last (from the replies' `server_pid`).
    server: Mutex<Option<ProcessWatch>>,
    _node: Node<Svc>,
}

/// Longest sleep between two looks at the estimator's liveness while a reply is due.
const LIVENESS_SLICE: Duration = Duration::from_millis(10);

impl EstimatorClient {
    /// Opens the services and waits (up to `timeout`) until the estimator answers a
    /// ping. Fails with [`IpcError::NoEstimator`] or [`IpcError::Timeout`] otherwise.
    pub fn connect(prefix: &str, timeout: Duration) -> Result<Self, IpcError> {
        let client = Self::open(prefix)?;
        client.wait_until_ready(timeout, || Ok(()))?;
        Ok(client)
    }

    /// Opens the services without waiting for an estimator.
    pub fn open(prefix: &str) -> Result<Self, IpcError> {
        let names = ServiceNames::new(prefix)?;
        let node = create_node("probebridge-estimator-client")?;
        let client = open_request_service(&node, &names)?
            .client_builder()
            .create()
            .map_err(|e| IpcError::iox("create estimator client", e))?;
        let request_notifier = notifier(&open_event_service(&node, &names.requests_event)?)?;
        let result_listener = listener(&open_event_service(&node, &names.results_event)?)?;
        Ok(Self {
            client,
            request_notifier,
            result_listener,
            next_request_id: AtomicU64::new(1),
            names,
            server: Mutex::new(None),
            _node: node,
        })
    }

    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    /// Pings until the estimator answers or `timeout` passes. Between attempts (only
    /// while no estimator is connected at all) it calls `check`, which can end the wait
    /// early (e.g. the estimator process exited), and sleeps 5 ms.
    pub(crate) fn wait_until_ready(
        &self,
        timeout: Duration,
        mut check: impl FnMut() -> Result<(), IpcError>,
    ) -> Result<Duration, IpcError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.ping(left) {
                Ok(rtt) => return Ok(rtt),
                Err(IpcError::NoEstimator(_)) if !left.is_zero() => {
                    check()?;
                    std::thread::sleep(Duration::from_millis(5).min(left));
                }
                Err(IpcError::NoEstimator(_)) => {
                    return Err(IpcError::Timeout {
                        prefix: self.names.prefix.clone(),
                        what: "a ping (no estimator connected)",
                        after: timeout,
                    })
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Round trip to the estimator; returns the time it took.
    pub fn ping(&self, timeout: Duration) -> Result<Duration, IpcError> {
        let t0 = Instant::now();
        self.request(EstimatorRequest::ping(), timeout)?;
        Ok(t0.elapsed())
    }

    /// Asks for the sphere through the samples of `run_id`. An estimator that cannot fit
    /// (unknown run, too few points, ...) answers with `ok == false` and an `error`.
    pub fn fit_sphere(&self, run_id: u64, timeout: Duration) -> Result<SphereResult, IpcError> {
        let reply = self.request(EstimatorRequest::fit_sphere(run_id), timeout)?;
        Ok(SphereResult::from_reply(&reply))
    }

    /// Drops the samples of `run_id`; returns how many there were (`UnknownRun` if none).
    pub fn forget(&self, run_id: u64, timeout: Duration) -> Result<(ReplyStatus, u64), IpcError> {
        let reply = self.request(EstimatorRequest::forget(run_id), timeout)?;
        Ok((reply.reply_status(), reply.n_points))
    }

    /// Asks the estimator to exit (it replies first).
    pub fn shutdown(&self, timeout: Duration) -> Result<(), IpcError> {
        self.request(EstimatorRequest::shutdown(), timeout)
            .map(|_| ())
    }

    /// Sends any request and waits for its reply: loan, write, send, notify the
    /// estimator, then sleep on `<prefix>/results/event` until the reply is there.
    pub fn request(
        &self,
        mut request: EstimatorRequest,
        timeout: Duration,
    ) -> Result<EstimatorReply, IpcError> {
        let deadline = Instant::now() + timeout;
        request.request_id = self.next_request_id.fetch_add(1, Ordering::Relaxed);
        let what = match request.request_kind() {
            Some(RequestKind::Ping) => "a ping",
            Some(RequestKind::FitSphere) => "a sphere fit request",
            Some(RequestKind::Forget) => "a forget request",
            Some(RequestKind::Shutdown) => "a shutdown request",
            Some(RequestKind::IdentifyData) => "an identification input chunk",
            Some(RequestKind::Identify) => "an identification request",
            Some(RequestKind::IdentifyResult) => "an identification result request",
            _ => "a request",
        };
        // Events from earlier replies must not count as the answer to this one.
        self.drain_events()?;
        let pending = self
            .client
            .loan_uninit()
            .map_err(|e| IpcError::iox("loan request", e))?
            .write_payload(request)
            .send()
            .map_err(|e| IpcError::iox("send request", e))?;
        if pending.number_of_server_connections() == 0 {
            return Err(IpcError::NoEstimator(self.names.prefix.clone()));
        }
        self.request_notifier
            .notify()
            .map_err(|e| IpcError::iox("notify the estimator", e))?;
        loop {
            if let Some(reply) = pending
                .receive()
                .map_err(|e| IpcError::iox("receive reply", e))?
            {
                let reply = *reply.payload();
                if reply.kind != request.kind || reply.request_id != request.request_id {
                    return Err(IpcError::WrongReply {
                        expected: request.kind,
                        got: reply.kind,
                    });
                }
                self.watch(reply.server_pid);
                return Ok(reply);
            }
            if !pending.is_connected() {
                // The server sends before it lets go of the request: look once more.
                if let Some(reply) = pending
                    .receive()
                    .map_err(|e| IpcError::iox("receive reply", e))?
                {
                    return Ok(*reply.payload());
                }
                return Err(IpcError::Dropped(self.names.prefix.clone()));
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(IpcError::Timeout {
                    prefix: self.names.prefix.clone(),
                    what,
                    after: timeout,
                });
            }
            self.result_listener
                .timed_wait(|_| {}, (deadline - now).min(LIVENESS_SLICE))
                .map_err(|e| IpcError::iox("wait for the reply event", e))?;
            if let Some(pid) = self.server_exited() {
                // It may have answered just before it ended.
                if let Some(reply) = pending
                    .receive()
                    .map_err(|e| IpcError::iox("receive reply", e))?
                {
                    return Ok(*reply.payload());
                }
                return Err(IpcError::Died {
                    prefix: self.names.prefix.clone(),
                    pid,
                    what,
                });
            }
        }
    }

    /// Watches the process that sent a reply (once per process).
    fn watch(&self, pid: u32) {
        if pid == 0 {
            return;
        }
        let mut server = self.server.lock().unwrap_or_else(|e| e.into_inner());
        if server.as_ref().is_some_and(|w| w.pid() == pid) {
            return;
        }
        // Without a pidfd (an old kernel) the request timeout still applies.
        *server = ProcessWatch::open(pid).ok();
    }

    /// The pid of the watched estimator if it has ended.
    fn server_exited(&self) -> Option<u32> {
        let server = self.server.lock().unwrap_or_else(|e| e.into_inner());
        server
            .as_ref()
            .filter(|w| w.has_exited())
            .map(ProcessWatch::pid)
    }

    fn drain_events(&self) -> Result<(), IpcError> {
        self.result_listener
            .try_wait(|_| {})
            .map(|_| ())
            .map_err(|e| IpcError::iox("read reply events", e))
    }
}

impl core::fmt::Debug for EstimatorClient {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("EstimatorClient")
            .field("service", &self.names.requests)
            .finish()
    }
}

/// The estimator running as a child process, with a client connected to it. Dropping it
/// asks the estimator to exit, kills it if it does not within a second, and removes the
/// iceoryx2 resources a killed estimator leaves behind.
pub struct EstimatorChild {
    client: Option<EstimatorClient>,
    child: Child,
    /// How it was started, to start it again ([`EstimatorChild::restart`]).
    recipe: Recipe,
}

/// A [`Command`] taken apart (it cannot be cloned), to build it again.
#[derive(Clone, Debug)]
struct Recipe {
    program: std::ffi::OsString,
    args: Vec<std::ffi::OsString>,
    envs: Vec<(std::ffi::OsString, Option<std::ffi::OsString>)>,
    dir: Option<std::path::PathBuf>,
    prefix: String,
    timeout: Duration,
}

impl Recipe {
    fn of(c: &Command, prefix: &str, timeout: Duration) -> Self {
        Self {
            program: c.get_program().to_owned(),
            args: c.get_args().map(ToOwned::to_owned).collect(),
            envs: c
                .get_envs()
                .map(|(k, v)| (k.to_owned(), v.map(ToOwned::to_owned)))
                .collect(),
            dir: c.get_current_dir().map(ToOwned::to_owned),
            prefix: prefix.to_string(),
            timeout,
        }
    }

    fn command(&self) -> Command {
        let mut c = Command::new(&self.program);
        c.args(&self.args);
        for (k, v) in &self.envs {
            match v {
                Some(v) => c.env(k, v),
                None => c.env_remove(k),
            };
        }
        if let Some(d) = &self.dir {
            c.current_dir(d);
        }
        c
    }
}

impl EstimatorChild {
    /// Starts `current_exe() estimator --service <prefix>` and waits until it answers a
    /// ping (polling, up to `timeout`).
    pub fn spawn(prefix: &str, timeout: Duration) -> Result<Self, IpcError> {
        Self::spawn_receiving(
            prefix,
            crate::estimator::armed::ArmedReceive::default(),
            timeout,
        )
    }

    /// As [`EstimatorChild::spawn`], with `--armed-receive` (config
    /// `[estimator] armed_receive`).
    pub fn spawn_receiving(
        prefix: &str,
        armed: crate::estimator::armed::ArmedReceive,
        timeout: Duration,
    ) -> Result<Self, IpcError> {
        let mut command = Command::new(std::env::current_exe()?);
        command.args([
            "estimator",
            "--service",
            prefix,
            "--armed-receive",
            armed.as_str(),
        ]);
        Self::spawn_command(command, prefix, timeout)
    }

    /// Like [`EstimatorChild::spawn`] with a caller-made command (another executable,
    /// extra arguments, environment); stdin is set to null.
    pub fn spawn_command(
        mut command: Command,
        prefix: &str,
        timeout: Duration,
    ) -> Result<Self, IpcError> {
        let recipe = Recipe::of(&command, prefix, timeout);
        // Open the client first, so a failure there does not leave a child behind.
        let client = EstimatorClient::open(prefix)?;
        // The estimator ends with the thread that started it, even when this process
        // is killed with no chance to clean up: no orphaned estimator keeps serving.
        // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            command.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let child = command.stdin(Stdio::null()).spawn()?;
        let mut this = Self {
            client: Some(client),
            child,
            recipe,
        };
        let child = &mut this.child;
        let ready = this
            .client
            .as_ref()
            .expect("client is set until drop")
            .wait_until_ready(timeout, || match child.try_wait()? {
                Some(status) => Err(IpcError::Process(format!(
                    "the estimator exited before answering ({status})"
                ))),
                None => Ok(()),
            });
        match ready {
            Ok(_) => Ok(this),
            Err(e) => Err(e), // drop kills the child
        }
    }

    pub fn client(&self) -> &EstimatorClient {
        self.client.as_ref().expect("client is set until drop")
    }

    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// `Some(status)` if the process has exited.
    pub fn try_wait(&mut self) -> Result<Option<std::process::ExitStatus>, IpcError> {
        Ok(self.child.try_wait()?)
    }

    /// Starts the estimator again, as it was started, in place of this one (which
    /// is killed if it still runs, and reaped); the resources the dead one left in
    /// iceoryx2 are removed first, so the new one can serve the same prefix. The new
    /// estimator knows nothing of the old one's samples and sessions.
    pub fn restart(&mut self) -> Result<(), IpcError> {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
        self.client = None;
        let _ = remove_stale_resources(Duration::from_millis(500));
        let r = &self.recipe;
        let fresh = Self::spawn_command(r.command(), &r.prefix.clone(), r.timeout)?;
        // The old handle's process is reaped and its client closed: dropping it
        // does nothing more.
        let _old = std::mem::replace(self, fresh);
        Ok(())
    }
}

impl Drop for EstimatorChild {
    fn drop(&mut self) {
        let asked = self
            .client
            .as_ref()
            .is_some_and(|c| c.shutdown(Duration::from_millis(500)).is_ok());
        self.client = None;
        if asked {
            let deadline = Instant::now() + Duration::from_secs(1);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
            let _ = remove_stale_resources(Duration::from_millis(500));
        }
    }
}

impl core::fmt::Debug for EstimatorChild {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("EstimatorChild")
            .field("pid", &self.child.id())
            .field("client", &self.client)
            .finish()
    }
}
