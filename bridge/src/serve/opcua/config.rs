//! The `[opcua]` section of the gateway configuration: where the OPC UA face listens,
//! which security it offers, who may do what, and its limits. The face is off unless
//! the section is there. Checked with the rest of the file, before anything is opened.

use serde::Deserialize;
use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};

/// The OPC UA face's settings (see the README's gateway page, "OPC UA face").
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpcuaSection {
    /// `opc.tcp://HOST:PORT` (HOST an IP address; port 0 takes any).
    #[serde(default = "default_listen")]
    pub listen: String,
    /// The host name in the endpoint URLs and the certificate (default: the listen
    /// address, or this machine's name when listening on every address).
    #[serde(default)]
    pub hostname: Option<String>,
    /// Endpoints offered: `basic256sha256-sign`, `basic256sha256-sign-encrypt`,
    /// `none` (anonymous reading only: no password crosses it).
    #[serde(default = "default_security")]
    pub security: Vec<String>,
    /// Anonymous clients may read and subscribe (never call the methods).
    #[serde(default = "default_true")]
    pub anonymous: bool,
    /// StartProgram is callable at all (by a user of the users file).
    #[serde(default)]
    pub may_start: bool,
    /// The certificate store: own/cert.der, private/private.pem (made on first start),
    /// trusted/ and rejected/ client certificates. Default: `opcua/pki` in the state
    /// directory.
    #[serde(default)]
    pub pki: Option<PathBuf>,
    /// The users file (`NAME:ARGON2-PHC` lines, readable by the service user only).
    /// Default: `opcua/users` in the state directory.
    #[serde(default)]
    pub users: Option<PathBuf>,
    /// The lifetime of the server certificate the gateway makes, in days.
    #[serde(default = "default_certificate_days")]
    pub certificate_days: u32,
    /// The addresses the certificate names when listening on every address (default:
    /// the host's addresses when it is made).
    #[serde(default)]
    pub certificate_addresses: Vec<IpAddr>,
    /// Trust every client certificate (only for a closed test network).
    #[serde(default)]
    pub trust_client_certs: bool,
    /// TCP connections served at once; more are closed at accept.
    #[serde(default = "default_max_connections")]
    pub max_connections: usize,
    #[serde(default = "default_max_sessions")]
    pub max_sessions: usize,
    #[serde(default = "default_session_timeout_ms")]
    pub session_timeout_ms: u64,
    #[serde(default = "default_max_subscriptions")]
    pub max_subscriptions_per_session: usize,
    #[serde(default = "default_max_items")]
    pub max_monitored_items_per_subscription: usize,
    /// Notifications a subscription keeps for a client that does not publish; the
    /// oldest go first beyond it.
    #[serde(default = "default_max_queued")]
    pub max_queued_notifications: usize,
    /// The last runs of the history shown under Measurements/LastRuns.
    #[serde(default = "default_last_runs")]
    pub last_runs: usize,
    /// Identification of the machine (OPC 40001-1); empty: not known.
    #[serde(default)]
    pub manufacturer: String,
    /// The manufacturer's URI (DI's ManufacturerUri); with the serial number it makes
    /// the machine's ProductInstanceUri.
    #[serde(default)]
    pub manufacturer_uri: String,
    #[serde(default)]
    pub model: String,
    #[serde(default)]
    pub serial_number: String,
}

fn default_listen() -> String {
    "opc.tcp://127.0.0.1:4840".into()
}
fn default_security() -> Vec<String> {
    vec![SIGN.into(), SIGN_ENCRYPT.into()]
}
fn default_true() -> bool {
    true
}
fn default_certificate_days() -> u32 {
    365
}
fn default_max_connections() -> usize {
    16
}
fn default_max_sessions() -> usize {
    8
}
fn default_session_timeout_ms() -> u64 {
    60_000
}
fn default_max_subscriptions() -> usize {
    4
}
fn default_max_items() -> usize {
    500
}
fn default_max_queued() -> usize {
    100
}
fn default_last_runs() -> usize {
    10
}

pub const NONE: &str = "none";
pub const SIGN: &str = "basic256sha256-sign";
pub const SIGN_ENCRYPT: &str = "basic256sha256-sign-encrypt";

/// One endpoint's security.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Security {
    None,
    Sign,
    SignAndEncrypt,
}

/// A key and why its value is refused.
pub type Invalid = (&'static str, String);

impl OpcuaSection {
    /// Relative paths are taken from the configuration's folder.
    pub fn anchor(&mut self, base: &Path) {
        for p in [self.pki.as_mut(), self.users.as_mut()]
            .into_iter()
            .flatten()
        {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
    }

    pub fn validate(&self) -> Result<(), Invalid> {
        self.bind()?;
        self.securities()?;
        if let Some(h) = &self.hostname {
            let ok = !h.is_empty()
                && h.len() <= 253
                && h.chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':'));
            if !ok {
                return Err(("opcua.hostname", format!("{h:?} is not a host name")));
            }
        }
        let ranges: [(&'static str, usize, std::ops::RangeInclusive<usize>); 6] = [
            ("opcua.max_connections", self.max_connections, 1..=256),
            ("opcua.max_sessions", self.max_sessions, 1..=256),
            (
                "opcua.max_subscriptions_per_session",
                self.max_subscriptions_per_session,
                1..=100,
            ),
            (
                "opcua.max_monitored_items_per_subscription",
                self.max_monitored_items_per_subscription,
                1..=10_000,
            ),
            (
                "opcua.max_queued_notifications",
                self.max_queued_notifications,
                1..=100_000,
            ),
            ("opcua.last_runs", self.last_runs, 0..=100),
        ];
        for (key, v, range) in ranges {
            if !range.contains(&v) {
                return Err((
                    key,
                    format!("{v} is outside {}..={}", range.start(), range.end()),
                ));
            }
        }
        if self.max_sessions > self.max_connections {
            return Err((
                "opcua.max_sessions",
                format!(
                    "{} is more than opcua.max_connections ({}): a session needs a connection",
                    self.max_sessions, self.max_connections
                ),
            ));
        }
        if !(1..=3650).contains(&self.certificate_days) {
            return Err((
                "opcua.certificate_days",
                format!("{} is outside 1..=3650", self.certificate_days),
            ));
        }
        if !(1_000..=3_600_000).contains(&self.session_timeout_ms) {
            return Err((
                "opcua.session_timeout_ms",
                format!("{} is outside 1000..=3600000", self.session_timeout_ms),
            ));
        }
        for (key, v) in [
            ("opcua.manufacturer", &self.manufacturer),
            ("opcua.manufacturer_uri", &self.manufacturer_uri),
            ("opcua.model", &self.model),
            ("opcua.serial_number", &self.serial_number),
        ] {
            if v.len() > 255 || v.chars().any(char::is_control) {
                return Err((key, "at most 255 characters, no control characters".into()));
            }
        }
        // An absolute URI: a scheme, a colon, no spaces (`https://machines.acme.example`).
        let uri = &self.manufacturer_uri;
        let scheme = uri.split(':').next().unwrap_or("");
        if !uri.is_empty()
            && (!uri.contains(':')
                || scheme.is_empty()
                || !scheme
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
                || uri.contains(char::is_whitespace))
        {
            return Err((
                "opcua.manufacturer_uri",
                format!("{uri:?} is no absolute URI (e.g. \"https://machines.acme.example\")"),
            ));
        }
        Ok(())
    }

    /// The address to bind, from `opc.tcp://HOST:PORT`.
    pub fn bind(&self) -> Result<SocketAddr, Invalid> {
        let bad = |why: &str| {
            (
                "opcua.listen",
                format!(
                    "{:?} is not opc.tcp://HOST:PORT with HOST an IP address ({why})",
                    self.listen
                ),
            )
        };
        let rest = self
            .listen
            .strip_prefix("opc.tcp://")
            .ok_or_else(|| bad("it must begin with opc.tcp://"))?;
        let rest = rest.strip_suffix('/').unwrap_or(rest);
        rest.parse::<SocketAddr>().map_err(|e| bad(&e.to_string()))
    }

    /// The endpoints' securities, in the order given.
    pub fn securities(&self) -> Result<Vec<Security>, Invalid> {
        if self.security.is_empty() {
            return Err(("opcua.security", "give at least one endpoint".into()));
        }
        let mut out = Vec::new();
        for s in &self.security {
            let sec = match s.as_str() {
                NONE => Security::None,
                SIGN => Security::Sign,
                SIGN_ENCRYPT => Security::SignAndEncrypt,
                other => {
                    return Err((
                        "opcua.security",
                        format!("{other:?}: expected {NONE:?}, {SIGN:?} or {SIGN_ENCRYPT:?}"),
                    ))
                }
            };
            if out.contains(&sec) {
                return Err(("opcua.security", format!("{s:?} is given twice")));
            }
            out.push(sec);
        }
        if out == [Security::None] && !self.anonymous {
            return Err((
                "opcua.security",
                "only \"none\" and opcua.anonymous = false: nobody could log in (passwords \
                 never cross an endpoint without security)"
                    .into(),
            ));
        }
        Ok(out)
    }

    /// The host name clients are told: `hostname`, else the listen address, else (for
    /// an unspecified address) this machine's name.
    pub fn advertised_host(&self, bind: SocketAddr) -> String {
        if let Some(h) = &self.hostname {
            return h.clone();
        }
        match bind.ip() {
            ip if ip.is_unspecified() => machine_hostname(),
            IpAddr::V6(v6) => format!("[{v6}]"),
            IpAddr::V4(v4) => v4.to_string(),
        }
    }
}

fn machine_hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most buf.len() bytes into our buffer.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    match std::str::from_utf8(&buf[..end]) {
        Ok(s) if rc == 0 && !s.is_empty() => s.to_string(),
        _ => "localhost".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section(toml_text: &str) -> OpcuaSection {
        toml::from_str(toml_text).unwrap()
    }

    #[test]
    fn the_defaults_listen_on_loopback_with_both_secured_endpoints() {
        let s = section("");
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.bind().unwrap(), "127.0.0.1:4840".parse().unwrap());
        assert_eq!(
            s.securities().unwrap(),
            [Security::Sign, Security::SignAndEncrypt]
        );
        assert!(s.anonymous && !s.may_start);
        assert_eq!(s.advertised_host(s.bind().unwrap()), "127.0.0.1");
    }

    #[test]
    fn bad_values_name_the_key_and_the_reason() {
        for (text, key, part) in [
            (
                "listen = \"tcp://1.2.3.4:4840\"",
                "opcua.listen",
                "opc.tcp://",
            ),
            (
                "listen = \"opc.tcp://gateway:4840\"",
                "opcua.listen",
                "IP address",
            ),
            ("security = [\"basic128\"]", "opcua.security", "expected"),
            ("security = []", "opcua.security", "at least one"),
            (
                "security = [\"none\"]\nanonymous = false",
                "opcua.security",
                "nobody",
            ),
            ("max_connections = 0", "opcua.max_connections", "outside"),
            (
                "max_connections = 2\nmax_sessions = 3",
                "opcua.max_sessions",
                "needs a connection",
            ),
            (
                "max_queued_notifications = 0",
                "opcua.max_queued_notifications",
                "outside",
            ),
            ("last_runs = 101", "opcua.last_runs", "outside"),
            (
                "session_timeout_ms = 10",
                "opcua.session_timeout_ms",
                "outside",
            ),
            ("hostname = \"a b\"", "opcua.hostname", "not a host name"),
            ("certificate_days = 0", "opcua.certificate_days", "outside"),
            ("model = \"a\\nb\"", "opcua.model", "control"),
            (
                "manufacturer_uri = \"acme machines\"",
                "opcua.manufacturer_uri",
                "no absolute URI",
            ),
            (
                "manufacturer_uri = \"https://acme.example/a b\"",
                "opcua.manufacturer_uri",
                "no absolute URI",
            ),
        ] {
            let (k, why) = section(text).validate().unwrap_err();
            assert_eq!(k, key, "{text}");
            assert!(why.contains(part), "{text}: {why}");
        }
    }
}
