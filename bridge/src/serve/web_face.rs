//! The read-only web face of the gateway (`[web] listen`, off unless configured): the
//! calibration trend, the latest measuring protocols and the service's status, over
//! HTTP/1.1 (hyper) on a tokio runtime of its own thread, like the PLC face.
//!
//! The same rules as the PLC face: at most `max_connections` at once (more are closed
//! at once), a request's head must arrive and the connection end within
//! `request_timeout_ms`; GET and HEAD only. No path from a request reaches the file
//! system: the protocols are a fixed list of file names in the logs folder, every
//! other answer is made in memory. Every stored string is escaped, in attributes too;
//! the Content-Security-Policy allows no script at all and no inline style on the
//! gateway's own pages.

use super::face_log::{Event, FaceLog, Limiter, SUMMARY_EVERY};
use super::gateway::{lock, Shared};
use super::measurement::{Origin, State};
use crate::history::trend::{self, escape, Alarm, Style};
use crate::history::{Filter, History, HistoryTarget, RunRow};
use bytes::Bytes;
use http_body_util::Full;
use hyper::header::{HeaderValue, ALLOW, CACHE_CONTROL, CONTENT_LENGTH, CONTENT_TYPE};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use std::convert::Infallible;
use std::fmt::Write;
use std::io;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::Mutex;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The measuring protocols the face serves, by their fixed file names.
pub const PROTOCOLS: [&str; 3] = [
    cycles::cycle451::measuring_log::KINEMATICS_LOG,
    cycles::measuring_log::probing3d::PROBING_3D_LOG,
    cycles::measuring_log::plane::PLANE_LOG,
];

/// The largest protocol file served.
const MAX_PROTOCOL_BYTES: u64 = 16 << 20;

/// The gateway's own pages: no script, style only from `/style.css`.
const CSP_PAGES: &str = "default-src 'none'; style-src 'self'; img-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";
/// The measuring protocols carry their style inline (they are files to carry away);
/// still no script, nothing loaded, and sandboxed.
const CSP_PROTOCOL: &str = "default-src 'none'; style-src 'unsafe-inline'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'; sandbox";

const STYLE_URL: &str = "/style.css";

/// What the pages are made of.
pub struct Site {
    pub shared: Shared,
    /// The history the trend page reads (None: history off).
    pub history: Option<HistoryTarget>,
    pub alarm: Alarm,
    /// Where the measuring protocols are written.
    pub logs: PathBuf,
    pub machine: String,
    /// What peers cause, counted and said sparingly.
    log: Mutex<FaceLog>,
    /// The trend page's history failures, said at most once per period.
    history_failed: Mutex<Limiter>,
}

fn lock_log(site: &Site) -> std::sync::MutexGuard<'_, FaceLog> {
    site.log.lock().unwrap_or_else(|e| e.into_inner())
}

#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub max_connections: usize,
    pub request_timeout: Duration,
}

pub struct WebFace {
    pub local_addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<io::Result<()>>>,
}

/// Starts the face `[web] listen` asks for (none: `None`) and says its address on
/// stdout, as the PLC face's.
pub fn start_configured(
    cfg: &super::config::GatewayConfig,
    shared: &Shared,
    machine: &str,
) -> Result<Option<WebFace>, String> {
    let Some(bind) = cfg.web_listen().map_err(|e| e.to_string())? else {
        return Ok(None);
    };
    let site = Site {
        shared: shared.clone(),
        history: cfg.history(),
        alarm: cfg.alarm(),
        logs: cfg
            .programs
            .out
            .clone()
            .unwrap_or_else(|| cfg.programs.folder.clone()),
        machine: machine.to_string(),
        log: Mutex::new(FaceLog::named("web face", Instant::now())),
        history_failed: Mutex::default(),
    };
    let limits = Limits {
        max_connections: cfg.web.max_connections,
        request_timeout: Duration::from_millis(cfg.web.request_timeout_ms),
    };
    let face = WebFace::start(site, bind, limits).map_err(|e| {
        format!(
            "{}: web.listen: cannot bind {bind}: {e}",
            cfg.path.display()
        )
    })?;
    tracing::info!(listen = %face.local_addr, "web face ready");
    crate::say!("probebridge serve: web face on http://{}", face.local_addr);
    Ok(Some(face))
}

impl WebFace {
    pub fn start(site: Site, bind: SocketAddr, limits: Limits) -> io::Result<Self> {
        let listener = std::net::TcpListener::bind(bind)?;
        listener.set_nonblocking(true)?;
        let local_addr = listener.local_addr()?;
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let site = Arc::new(site);
        let thread = std::thread::Builder::new()
            .name("probebridge-web-face".into())
            .spawn(move || {
                tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()?
                    .block_on(serve(listener, site, limits, rx))
            })?;
        Ok(Self {
            local_addr,
            stop: Some(tx),
            thread: Some(thread),
        })
    }
}

impl Drop for WebFace {
    fn drop(&mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

async fn serve(
    listener: std::net::TcpListener,
    site: Arc<Site>,
    limits: Limits,
    mut stop: tokio::sync::oneshot::Receiver<()>,
) -> io::Result<()> {
    let listener = tokio::net::TcpListener::from_std(listener)?;
    let slots = Arc::new(tokio::sync::Semaphore::new(limits.max_connections));
    let mut summary = tokio::time::interval(SUMMARY_EVERY / 4);
    loop {
        let (stream, addr) = tokio::select! {
            _ = &mut stop => return Ok(()),
            _ = summary.tick() => {
                let open = limits.max_connections - slots.available_permits();
                lock_log(&site).log_summary(Instant::now(), open, limits.max_connections);
                continue;
            }
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    if let Some(held) = lock_log(&site).count(Event::AcceptError, Instant::now()) {
                        tracing::warn!("web face: {e} ({held} more accept errors since the last such line)");
                    }
                    continue;
                }
            },
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            if let Some(held) = lock_log(&site).count(Event::RefusedFull, Instant::now()) {
                tracing::warn!(
                    %addr,
                    "web face: connection limit reached; closed ({held} more closed since the last such line)"
                );
            }
            drop(stream);
            continue;
        };
        lock_log(&site).count(Event::Accepted, Instant::now());
        let site = site.clone();
        tokio::spawn(async move {
            let _slot = slot;
            let service = hyper::service::service_fn(move |req| {
                let site = site.clone();
                async move { Ok::<_, Infallible>(answer(site, req).await) }
            });
            let conn = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(limits.request_timeout)
                .serve_connection(TokioIo::new(stream), service);
            // The whole connection is bounded too: a client that reads slowly, or keeps
            // a connection open, does not hold a slot for ever.
            match tokio::time::timeout(limits.request_timeout, conn).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::debug!(%addr, "web face: {e}"),
                Err(_) => tracing::debug!(%addr, "web face: connection timed out"),
            }
        });
    }
}

/// A page or file answered.
struct Answer {
    status: StatusCode,
    content_type: &'static str,
    csp: &'static str,
    body: Vec<u8>,
}

impl Answer {
    fn html(body: String) -> Self {
        Self {
            status: StatusCode::OK,
            content_type: "text/html; charset=utf-8",
            csp: CSP_PAGES,
            body: body.into_bytes(),
        }
    }

    fn error(status: StatusCode, text: &str) -> Self {
        let mut html = String::new();
        let _ = write!(
            html,
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><link rel=\"stylesheet\" href=\"{STYLE_URL}\"></head><body><h1>{}</h1><p>{}</p><p><a href=\"/\">status</a></p></body></html>\n",
            status.as_u16(),
            status,
            escape(text)
        );
        Self {
            status,
            ..Self::html(html)
        }
    }
}

async fn answer(site: Arc<Site>, req: Request<hyper::body::Incoming>) -> Response<Full<Bytes>> {
    let method = req.method().clone();
    let path = req.uri().path().to_string();
    drop(req);
    let a = if method != Method::GET && method != Method::HEAD {
        Answer::error(
            StatusCode::METHOD_NOT_ALLOWED,
            "this face is read-only: GET and HEAD only",
        )
    } else {
        // The history and the files are read off the runtime's thread.
        tokio::task::spawn_blocking(move || route(&site, &path))
            .await
            .unwrap_or_else(|e| {
                tracing::error!("web face: {e}");
                Answer::error(StatusCode::INTERNAL_SERVER_ERROR, "the page failed")
            })
    };
    let len = a.body.len();
    let mut resp = Response::new(Full::new(Bytes::from(a.body)));
    *resp.status_mut() = a.status;
    let h = resp.headers_mut();
    h.insert(CONTENT_TYPE, HeaderValue::from_static(a.content_type));
    // Explicit, so a HEAD answer says the length the GET would have (hyper sends no
    // body to a HEAD).
    h.insert(CONTENT_LENGTH, HeaderValue::from(len));
    h.insert("content-security-policy", HeaderValue::from_static(a.csp));
    h.insert(
        "x-content-type-options",
        HeaderValue::from_static("nosniff"),
    );
    h.insert("referrer-policy", HeaderValue::from_static("no-referrer"));
    h.insert("x-frame-options", HeaderValue::from_static("DENY"));
    h.insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if a.status == StatusCode::METHOD_NOT_ALLOWED {
        h.insert(ALLOW, HeaderValue::from_static("GET, HEAD"));
    }
    tracing::debug!(%method, status = a.status.as_u16(), len, "web face");
    resp
}

/// The fixed list of what the face answers.
fn route(site: &Site, path: &str) -> Answer {
    match path {
        "/" | "/status" => Answer::html(status_page(site)),
        "/style.css" => Answer {
            status: StatusCode::OK,
            content_type: "text/css; charset=utf-8",
            csp: CSP_PAGES,
            body: trend::CSS.as_bytes().to_vec(),
        },
        "/trend" => trend_page(site, None),
        "/protocols" => Answer::html(protocols_page(site)),
        _ => {
            if let Some(n) = path.strip_prefix("/trend/") {
                // Only the canonical number: one URL per page.
                return match n.parse::<usize>() {
                    Ok(k) if k >= 1 && k.to_string() == n => trend_page(site, Some(k - 1)),
                    _ => Answer::error(StatusCode::NOT_FOUND, "no such machine page"),
                };
            }
            if let Some(name) = path.strip_prefix("/protocols/") {
                if let Some(&fixed) = PROTOCOLS.iter().find(|p| **p == name) {
                    return protocol(site, fixed);
                }
            }
            Answer::error(StatusCode::NOT_FOUND, "no such page")
        }
    }
}

fn runs(site: &Site) -> Result<Vec<RunRow>, String> {
    let Some(target) = &site.history else {
        return Err("the history is off ([history] enabled = false)".into());
    };
    let mut h = History::open(target).map_err(|e| e.to_string())?;
    h.list(&Filter::default()).map_err(|e| e.to_string())
}

/// `/trend`: the machine's page, or the index of several machines; `/trend/N`: the
/// page of machine N of the index.
fn trend_page(site: &Site, machine: Option<usize>) -> Answer {
    let runs = match runs(site) {
        Ok(r) => r,
        Err(e) => {
            // A peer asks as often as it likes: said once per period, counted.
            if let Some(held) = site
                .history_failed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .pass(Instant::now())
            {
                tracing::warn!("web face: {e} ({held} more such pages since the last such line)");
            }
            return Answer::error(StatusCode::SERVICE_UNAVAILABLE, &e);
        }
    };
    let names = trend::machines(&runs);
    let style = Style::Linked(STYLE_URL);
    match machine {
        None if names.len() <= 1 => {
            let name = names.first().map_or(site.machine.as_str(), String::as_str);
            Answer::html(trend::machine_page(&runs, name, &site.alarm, style, None))
        }
        None => Answer::html(trend::index_page(&runs, &site.alarm, style, &|i| {
            format!("/trend/{}", i + 1)
        })),
        Some(i) => match names.get(i) {
            Some(name) => Answer::html(trend::machine_page(
                &runs,
                name,
                &site.alarm,
                style,
                Some("/trend"),
            )),
            None => Answer::error(StatusCode::NOT_FOUND, "no such machine page"),
        },
    }
}

fn protocol(site: &Site, name: &'static str) -> Answer {
    let path = site.logs.join(name);
    let read = std::fs::File::open(&path).and_then(|f| {
        let meta = f.metadata()?;
        if !meta.is_file() || meta.len() > MAX_PROTOCOL_BYTES {
            return Err(io::Error::other("not a protocol file"));
        }
        let mut body = Vec::new();
        io::Read::read_to_end(&mut io::Read::take(f, MAX_PROTOCOL_BYTES), &mut body)?;
        Ok(body)
    });
    match read {
        Ok(body) => Answer {
            status: StatusCode::OK,
            content_type: if name.ends_with(".html") {
                "text/html; charset=utf-8"
            } else {
                "text/plain; charset=utf-8"
            },
            csp: CSP_PROTOCOL,
            body,
        },
        Err(_) => Answer::error(
            StatusCode::NOT_FOUND,
            "this protocol has not been written yet",
        ),
    }
}

/// The head and the links between the pages; `refresh`: reloaded every 2 s.
fn nav(html: &mut String, title: &str, refresh: bool) {
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">{}<title>probebridge: {}</title><link rel=\"stylesheet\" href=\"{STYLE_URL}\"></head><body>\n<nav><a href=\"/\">status</a><a href=\"/trend\">calibration trend</a><a href=\"/protocols\">measuring protocols</a></nav>\n",
        if refresh {
            "<meta http-equiv=\"refresh\" content=\"2\">"
        } else {
            ""
        },
        escape(title)
    );
}

fn protocols_page(site: &Site) -> String {
    let mut html = String::new();
    nav(&mut html, "measuring protocols", false);
    html.push_str("<h1>Latest measuring protocols</h1>\n<table class=\"protocols\"><tr><th class=\"l\">protocol</th><th class=\"l\">written (UTC)</th><th>bytes</th></tr>\n");
    for name in PROTOCOLS {
        let meta = std::fs::metadata(site.logs.join(name)).ok();
        match meta.filter(std::fs::Metadata::is_file) {
            Some(m) => {
                let written = m
                    .modified()
                    .ok()
                    .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                    .map_or(String::new(), |d| {
                        crate::history::time::format_utc(d.as_secs())
                    });
                let _ = writeln!(
                    html,
                    "<tr><td class=\"l\"><a href=\"/protocols/{name}\">{name}</a></td><td class=\"l\">{written}</td><td>{}</td></tr>",
                    m.len()
                );
            }
            None => {
                let _ = writeln!(
                    html,
                    "<tr><td class=\"l\">{name}</td><td class=\"l\">not written yet</td><td></td></tr>"
                );
            }
        }
    }
    html.push_str("</table>\n</body></html>\n");
    html
}

/// The service's state as every face shows it; the browser reloads it every 2 s (a
/// meta refresh: no script).
fn status_page(site: &Site) -> String {
    let status = *lock(&site.shared).service.status();
    let state = status.state;
    let mut html = String::new();
    nav(&mut html, "status", true);
    let started = |origin| match origin {
        Some(Origin::Plc { seq }) => format!("by the PLC, request {seq}"),
        Some(Origin::OpcUa) => "over OPC UA".into(),
        None => "none".into(),
    };
    // The cycle is that of the results a run that ended done left.
    let last = match status.origin {
        None => "none yet".to_string(),
        origin => format!(
            "program {} ({}), cycle {}",
            status.program,
            started(origin),
            status.cycle
        ),
    };
    let run = if state == State::Busy {
        format!("program {} ({})", status.program, started(status.origin))
    } else {
        "none".into()
    };
    let _ = write!(
        html,
        "<h1>probebridge gateway: {}</h1>\n<table class=\"status\">\
         <tr><th class=\"l\">state</th><td id=\"state\">{}</td></tr>\
         <tr><th class=\"l\">machine</th><td id=\"machine-ok\" class=\"{}\">{}</td></tr>\
         <tr><th class=\"l\">current run</th><td id=\"current-run\">{}</td></tr>\
         <tr><th class=\"l\">progress</th><td id=\"progress\"><progress max=\"1000\" value=\"{}\"></progress> {:.1} %, {} point(s)</td></tr>\
         <tr><th class=\"l\">last run</th><td>{}</td></tr>",
        escape(&site.machine),
        state.name(),
        if status.machine_ok { "ok" } else { "bad" },
        if status.machine_ok {
            "ok"
        } else {
            "not ok: opening it again"
        },
        escape(&run),
        status.progress_permille,
        f64::from(status.progress_permille) / 10.0,
        status.point,
        escape(&last),
    );
    if state == State::Error {
        let _ = write!(
            html,
            "<tr><th class=\"l\">error</th><td class=\"bad\">kind {}, code {}</td></tr>",
            status.error_kind, status.error_code
        );
    }
    html.push_str("</table>\n</body></html>\n");
    html
}
