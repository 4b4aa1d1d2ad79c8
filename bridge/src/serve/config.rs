//! The gateway configuration (`/etc/probebridge/gateway.toml`): which machine, where the
//! programs are, and the PLC face. Unknown keys and out-of-range values are refused with
//! the file, the key and the reason, before anything is opened.

use serde::Deserialize;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub const DEFAULT_PATH: &str = "/etc/probebridge/gateway.toml";
pub const DEFAULT_HISTORY: &str = "/var/lib/probebridge/history.sqlite";

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GatewayConfig {
    #[serde(skip)]
    pub path: PathBuf,
    pub machine: MachineSection,
    pub programs: ProgramsSection,
    #[serde(default)]
    pub plc: PlcSection,
    #[serde(default)]
    pub history: HistorySection,
    #[serde(default)]
    pub web: WebSection,
    #[serde(default)]
    pub estimator: EstimatorSection,
    /// The OPC UA face: off unless the section is there.
    #[serde(default)]
    pub opcua: Option<super::opcua::config::OpcuaSection>,
}

/// `[estimator]`: the estimator process the gateway starts.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// `"auto"` (default): poll for the contact during probing moves where the machine
    /// has a CPU to spare; `"off"`: always sleep until woken.
    #[serde(default)]
    pub armed_receive: crate::estimator::ArmedReceive,
}

/// The read-only web face (trend page, measuring protocols, status): off unless
/// `listen` is given.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WebSection {
    /// `HOST:PORT`, or a port alone for loopback (127.0.0.1).
    #[serde(default)]
    pub listen: Option<String>,
    /// Connections served at once; more are closed at once.
    #[serde(default = "default_web_connections")]
    pub max_connections: usize,
    /// A request must arrive, and its answer go out, within this time.
    #[serde(default = "default_web_timeout_ms")]
    pub request_timeout_ms: u64,
}

impl Default for WebSection {
    fn default() -> Self {
        Self {
            listen: None,
            max_connections: default_web_connections(),
            request_timeout_ms: default_web_timeout_ms(),
        }
    }
}

fn default_web_connections() -> usize {
    16
}
fn default_web_timeout_ms() -> u64 {
    10_000
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistorySection {
    /// Record every run (default: yes).
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// The SQLite file of this gateway.
    #[serde(default = "default_sqlite")]
    pub sqlite: PathBuf,
    /// A central PostgreSQL server instead (`postgres://user:password@host:port/db`):
    /// the same tables, shared by many gateways.
    #[serde(default)]
    pub postgres: Option<String>,
    /// The spool for ends of runs the history could not take (see
    /// [`GatewayConfig::spool_path`] for the default).
    #[serde(default)]
    pub spool: Option<PathBuf>,
    /// PostgreSQL: the longest wait for a connection.
    #[serde(default = "default_connect_timeout_ms")]
    pub connect_timeout_ms: u64,
    /// The longest wait for one statement or transaction (SQLite: for another
    /// process's lock); a start waits this long at most for its `running` row.
    #[serde(default = "default_statement_timeout_ms")]
    pub statement_timeout_ms: u64,
    /// PostgreSQL: TCP keepalive, idle seconds before the first probe.
    #[serde(default = "default_keepalive_s")]
    pub keepalive_s: u64,
    /// The trend page marks a run whose identified position error (or dispersion)
    /// changed by more than this since the previous run, µm.
    #[serde(default = "default_alarm_um")]
    pub alarm_um: f64,
    /// The same for orientation errors, arcsec.
    #[serde(default = "default_alarm_arcsec")]
    pub alarm_arcsec: f64,
}

fn default_alarm_um() -> f64 {
    crate::history::trend::DEFAULT_ALARM_UM
}
fn default_alarm_arcsec() -> f64 {
    crate::history::trend::DEFAULT_ALARM_ARCSEC
}

impl Default for HistorySection {
    fn default() -> Self {
        Self {
            enabled: true,
            sqlite: default_sqlite(),
            postgres: None,
            spool: None,
            connect_timeout_ms: default_connect_timeout_ms(),
            statement_timeout_ms: default_statement_timeout_ms(),
            keepalive_s: default_keepalive_s(),
            alarm_um: default_alarm_um(),
            alarm_arcsec: default_alarm_arcsec(),
        }
    }
}

fn default_connect_timeout_ms() -> u64 {
    crate::history::Timeouts::default().connect.as_millis() as u64
}
fn default_statement_timeout_ms() -> u64 {
    crate::history::Timeouts::default().statement.as_millis() as u64
}
fn default_keepalive_s() -> u64 {
    crate::history::Timeouts::default().keepalive.as_secs()
}

fn default_true() -> bool {
    true
}
fn default_sqlite() -> PathBuf {
    PathBuf::from(DEFAULT_HISTORY)
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Machine configuration of the real machine (its `[bus] kind` says CANopen or
    /// Modbus).
    pub config: Option<PathBuf>,
    /// Or a simulation scenario: the built-in simulator.
    pub scenario: Option<PathBuf>,
    /// SocketCAN interface of a CANopen machine.
    pub can: Option<String>,
    /// Address of the PLC of a Modbus machine (overrides the machine file).
    pub modbus: Option<String>,
    /// The simulator paces moves in real time.
    #[serde(default)]
    pub realtime: bool,
    /// iceoryx2 service prefix shared with the estimator process.
    #[serde(default = "default_service")]
    pub service: String,
    /// The active kinematics file (cycles 450/451); default: in the machine's folder of
    /// the state directory ([`crate::machine_state`]).
    pub kinematics: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgramsSection {
    /// Folder of the NC programs; number NNN selects `NNN.h`.
    pub folder: PathBuf,
    /// Where measuring logs go (default: `protocols/` in the machine's folder of the
    /// state directory).
    pub out: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcSection {
    /// Modbus TCP address of the PLC face; port 0 takes any free port.
    #[serde(default = "default_listen")]
    pub listen: String,
    /// Word order of 32-bit values: "high_first" (ABCD) or "low_first" (CDAB).
    #[serde(default = "default_word_order")]
    pub word_order: String,
    /// While busy, a PLC heartbeat unchanged for this long aborts the motion; 0: off.
    #[serde(default = "default_heartbeat_timeout_ms")]
    pub heartbeat_timeout_ms: u64,
    /// Scale of the 32-bit integer copies of the results (value x scale, rounded).
    #[serde(default = "default_int_scale")]
    pub int_scale: f64,
    /// Connections served at once; more are refused at accept (unless the oldest
    /// silent one has been silent for `owner_timeout_ms`: it is closed for the new).
    #[serde(default = "default_max_connections")]
    pub max_connections: u64,
    /// Connections of one peer address at most (absent: half of `max_connections`,
    /// rounded up): one host's flood leaves room for the PLC.
    pub max_connections_per_peer: Option<u64>,
    /// A connection that owns the request block and says nothing for this long loses
    /// it to the next writer.
    #[serde(default = "default_owner_timeout_ms")]
    pub owner_timeout_ms: u64,
    /// Only these peers (addresses, CIDR networks) are served; absent: any peer.
    #[serde(default)]
    pub allow: Option<Vec<String>>,
}

impl Default for PlcSection {
    fn default() -> Self {
        Self {
            listen: default_listen(),
            word_order: default_word_order(),
            heartbeat_timeout_ms: default_heartbeat_timeout_ms(),
            int_scale: default_int_scale(),
            max_connections: default_max_connections(),
            max_connections_per_peer: None,
            owner_timeout_ms: default_owner_timeout_ms(),
            allow: None,
        }
    }
}

fn default_service() -> String {
    crate::commands::default_service()
}
fn default_listen() -> String {
    "127.0.0.1:502".into()
}
fn default_word_order() -> String {
    "high_first".into()
}
fn default_heartbeat_timeout_ms() -> u64 {
    2000
}
fn default_int_scale() -> f64 {
    10_000.0
}
fn default_max_connections() -> u64 {
    8
}
fn default_owner_timeout_ms() -> u64 {
    10_000
}

/// `plc.max_connections` at most (each one a file descriptor and a task).
pub const MAX_CONNECTIONS: u64 = 256;
/// `plc.owner_timeout_ms` range: at least a few PLC cycles, at most 10 min.
pub const MIN_OWNER_TIMEOUT_MS: u64 = 500;
pub const MAX_OWNER_TIMEOUT_MS: u64 = 600_000;

#[derive(Debug, thiserror::Error)]
pub enum GatewayConfigError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: {key}: {reason}")]
    Invalid {
        path: PathBuf,
        key: String,
        reason: String,
    },
}

impl GatewayConfig {
    /// Reads (at most `hal::config::MAX_CONFIG_BYTES`: `/dev/zero` is refused at once)
    /// and validates.
    pub fn load(path: &Path) -> Result<Self, GatewayConfigError> {
        let text =
            hal::config::read_config_text(path).map_err(|source| GatewayConfigError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        Self::parse(&text, path)
    }

    /// Parses and validates; relative paths are taken from the file's folder.
    pub fn parse(text: &str, path: &Path) -> Result<Self, GatewayConfigError> {
        let mut cfg: GatewayConfig =
            toml::from_str(text).map_err(|e| GatewayConfigError::Parse {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        cfg.path = path.to_path_buf();
        // A bare file name (`--config gateway.toml`) has the empty path as its parent.
        let base = match path.parent() {
            Some(folder) if !folder.as_os_str().is_empty() => folder,
            _ => Path::new("."),
        };
        let anchor = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        for p in [
            cfg.machine.config.as_mut(),
            cfg.machine.scenario.as_mut(),
            cfg.machine.kinematics.as_mut(),
            Some(&mut cfg.programs.folder),
            cfg.programs.out.as_mut(),
            Some(&mut cfg.history.sqlite),
            cfg.history.spool.as_mut(),
        ]
        .into_iter()
        .flatten()
        {
            anchor(p);
        }
        if let Some(o) = cfg.opcua.as_mut() {
            o.anchor(base);
        }
        cfg.validate()?;
        Ok(cfg)
    }

    fn invalid(&self, key: &str, reason: impl Into<String>) -> GatewayConfigError {
        GatewayConfigError::Invalid {
            path: self.path.clone(),
            key: key.into(),
            reason: reason.into(),
        }
    }

    fn validate(&self) -> Result<(), GatewayConfigError> {
        let m = &self.machine;
        match (&m.config, &m.scenario) {
            (None, None) => {
                return Err(self.invalid(
                    "machine",
                    "give machine.config (real machine) or machine.scenario (simulator)",
                ))
            }
            (Some(_), Some(_)) => {
                return Err(self.invalid(
                    "machine.scenario",
                    "give either machine.config or machine.scenario, not both",
                ))
            }
            _ => {}
        }
        if m.can.is_some() && m.modbus.is_some() {
            return Err(self.invalid("machine.modbus", "give either can or modbus, not both"));
        }
        if m.service.is_empty() || m.service.len() > 64 {
            return Err(self.invalid("machine.service", "must be 1..64 characters"));
        }
        if !self.programs.folder.is_dir() {
            return Err(self.invalid(
                "programs.folder",
                format!("{} is not a folder", self.programs.folder.display()),
            ));
        }
        if let Some(url) = &self.history.postgres {
            if !matches!(
                crate::history::HistoryTarget::parse(url),
                crate::history::HistoryTarget::Postgres(_)
            ) {
                return Err(self.invalid(
                    "history.postgres",
                    "expected a URL postgres://user:password@host:port/database",
                ));
            }
        } else if self.history.enabled {
            let folder = self.history.sqlite.parent().unwrap_or(Path::new("."));
            if !folder.is_dir() {
                return Err(self.invalid(
                    "history.sqlite",
                    format!("the folder {} does not exist", folder.display()),
                ));
            }
        }
        self.validate_history()?;
        for (key, v) in [
            ("history.alarm_um", self.history.alarm_um),
            ("history.alarm_arcsec", self.history.alarm_arcsec),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 1e6) {
                return Err(self.invalid(key, "must be a number in (0, 1e6]"));
            }
        }
        self.web_listen()?;
        if !(1..=1024).contains(&self.web.max_connections) {
            return Err(self.invalid("web.max_connections", "must be 1..1024"));
        }
        if !(100..=600_000).contains(&self.web.request_timeout_ms) {
            return Err(self.invalid("web.request_timeout_ms", "must be 100..600000"));
        }
        self.listen()?;
        self.word_order()?;
        let p = &self.plc;
        if p.heartbeat_timeout_ms > 600_000 {
            return Err(self.invalid(
                "plc.heartbeat_timeout_ms",
                "at most 600000 (0 turns the check off)",
            ));
        }
        if !(p.int_scale.is_finite() && p.int_scale >= 1.0 && p.int_scale <= 1e9) {
            return Err(self.invalid("plc.int_scale", "must be a number in 1..1e9"));
        }
        if !(1..=MAX_CONNECTIONS).contains(&p.max_connections) {
            return Err(self.invalid(
                "plc.max_connections",
                format!("{} is outside 1..{MAX_CONNECTIONS}", p.max_connections),
            ));
        }
        if !(1..=p.max_connections).contains(&self.per_peer_cap()) {
            let why = format!("{} is outside 1..plc.max_connections", self.per_peer_cap());
            return Err(self.invalid("plc.max_connections_per_peer", why));
        }
        if !(MIN_OWNER_TIMEOUT_MS..=MAX_OWNER_TIMEOUT_MS).contains(&p.owner_timeout_ms) {
            return Err(self.invalid(
                "plc.owner_timeout_ms",
                format!(
                    "{} is outside {MIN_OWNER_TIMEOUT_MS}..{MAX_OWNER_TIMEOUT_MS}",
                    p.owner_timeout_ms
                ),
            ));
        }
        self.allow()?;
        if let Some(o) = &self.opcua {
            o.validate().map_err(|(key, why)| self.invalid(key, why))?;
        }
        Ok(())
    }

    fn validate_history(&self) -> Result<(), GatewayConfigError> {
        let h = &self.history;
        for (key, value, range) in [
            (
                "history.connect_timeout_ms",
                h.connect_timeout_ms,
                100..=60_000,
            ),
            (
                "history.statement_timeout_ms",
                h.statement_timeout_ms,
                100..=10_000,
            ),
            ("history.keepalive_s", h.keepalive_s, 1..=3600),
        ] {
            if !range.contains(&value) {
                return Err(self.invalid(
                    key,
                    format!("{value} is outside {}..={}", range.start(), range.end()),
                ));
            }
        }
        if let Some(spool) = &h.spool {
            let folder = spool.parent().unwrap_or(Path::new("."));
            if !folder.is_dir() {
                return Err(self.invalid(
                    "history.spool",
                    format!("the folder {} does not exist", folder.display()),
                ));
            }
        }
        Ok(())
    }

    pub fn history_timeouts(&self) -> crate::history::Timeouts {
        let h = &self.history;
        crate::history::Timeouts {
            connect: Duration::from_millis(h.connect_timeout_ms),
            statement: Duration::from_millis(h.statement_timeout_ms),
            keepalive: Duration::from_secs(h.keepalive_s),
        }
    }

    /// The spool's file: `[history] spool`; else `$STATE_DIRECTORY/history.spool`
    /// (systemd's `StateDirectory=`); else beside the SQLite file (`NAME.spool`), or
    /// for PostgreSQL `$XDG_STATE_HOME/probebridge/history.spool` (default
    /// `~/.local/state`).
    pub fn spool_path(&self) -> PathBuf {
        if let Some(p) = &self.history.spool {
            return p.clone();
        }
        let state = std::env::var_os("STATE_DIRECTORY").filter(|s| !s.is_empty());
        if let Some(dirs) = state {
            // systemd lists several as a:b; the first is this unit's own.
            let first = std::env::split_paths(&dirs).next().unwrap_or_default();
            return first.join("history.spool");
        }
        if self.history.postgres.is_none() {
            return self.history.sqlite.with_extension("spool");
        }
        let xdg = std::env::var_os("XDG_STATE_HOME")
            .filter(|s| !s.is_empty())
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".local/state")))
            .unwrap_or_else(|| PathBuf::from("/var/lib"));
        xdg.join("probebridge").join("history.spool")
    }

    /// The peers the PLC face serves.
    pub fn allow(&self) -> Result<super::peer_allow::AllowList, GatewayConfigError> {
        match &self.plc.allow {
            None => Ok(super::peer_allow::AllowList::any()),
            Some(entries) => super::peer_allow::AllowList::parse(entries)
                .map_err(|e| self.invalid("plc.allow", e)),
        }
    }

    pub fn per_peer_cap(&self) -> u64 {
        (self.plc.max_connections_per_peer).unwrap_or(self.plc.max_connections.div_ceil(2))
    }

    pub fn owner_timeout(&self) -> Duration {
        Duration::from_millis(self.plc.owner_timeout_ms)
    }

    pub fn listen(&self) -> Result<SocketAddr, GatewayConfigError> {
        self.plc.listen.parse().map_err(|e| {
            self.invalid(
                "plc.listen",
                format!("{:?} is not an address HOST:PORT ({e})", self.plc.listen),
            )
        })
    }

    /// The web face's address, if it is on: `HOST:PORT`, or a port alone on loopback.
    pub fn web_listen(&self) -> Result<Option<SocketAddr>, GatewayConfigError> {
        let Some(l) = &self.web.listen else {
            return Ok(None);
        };
        let addr = match l.parse::<u16>() {
            Ok(port) => Ok(SocketAddr::from(([127, 0, 0, 1], port))),
            Err(_) => l.parse::<SocketAddr>(),
        };
        addr.map(Some).map_err(|e| {
            self.invalid(
                "web.listen",
                format!("{l:?} is not an address HOST:PORT or a port ({e})"),
            )
        })
    }

    /// The trend page's alarm thresholds.
    pub fn alarm(&self) -> crate::history::trend::Alarm {
        crate::history::trend::Alarm {
            um: self.history.alarm_um,
            arcsec: self.history.alarm_arcsec,
        }
    }

    pub fn word_order(&self) -> Result<super::register_map::WordOrder, GatewayConfigError> {
        match self.plc.word_order.as_str() {
            "high_first" => Ok(super::register_map::WordOrder::HighFirst),
            "low_first" => Ok(super::register_map::WordOrder::LowFirst),
            other => Err(self.invalid(
                "plc.word_order",
                format!("{other:?}: expected \"high_first\" or \"low_first\""),
            )),
        }
    }

    /// Where the history goes, when history is on: the PostgreSQL server if named,
    /// else the SQLite file.
    pub fn history(&self) -> Option<crate::history::HistoryTarget> {
        use crate::history::HistoryTarget;
        self.history.enabled.then(|| match &self.history.postgres {
            Some(url) => HistoryTarget::Postgres(url.clone()),
            None => HistoryTarget::Sqlite(self.history.sqlite.clone()),
        })
    }

    pub fn heartbeat_timeout(&self) -> Option<Duration> {
        (self.plc.heartbeat_timeout_ms > 0)
            .then(|| Duration::from_millis(self.plc.heartbeat_timeout_ms))
    }

    /// How `Session::open` reaches the machine.
    pub fn machine_options(&self) -> crate::session::options::MachineOptions {
        crate::session::options::MachineOptions {
            scenario: self.machine.scenario.clone(),
            machine: self.machine.config.clone(),
            can: self.machine.can.clone(),
            modbus: self.machine.modbus.clone(),
            realtime: self.machine.realtime,
            service: self.machine.service.clone(),
            candump: None,
            bus_faults: None,
            // The machine thread sets the gateway's own (re-armable) stop request.
            abort: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<GatewayConfig, GatewayConfigError> {
        let dir = std::env::temp_dir();
        let text = format!("{text}\n[history]\nsqlite = \"h.sqlite\"\n");
        GatewayConfig::parse(&text, &dir.join("gateway.toml"))
    }

    #[test]
    fn minimal_config_takes_the_defaults() {
        let c = parse("[machine]\nscenario = \"s.toml\"\n[programs]\nfolder = \".\"\n").unwrap();
        assert!(matches!(
            c.history(),
            Some(crate::history::HistoryTarget::Sqlite(p)) if p.starts_with(std::env::temp_dir())
        ));
        let e = GatewayConfig::parse(
            "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n[history]\nsqlite = \"/nonexistent/h.sqlite\"\n",
            &std::env::temp_dir().join("gateway.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("history.sqlite"), "{e}");
        assert_eq!(c.plc.listen, "127.0.0.1:502");
        assert_eq!(
            c.web_listen().unwrap(),
            None,
            "the web face is off by default"
        );
        assert_eq!(c.plc.max_connections, 8);
        assert_eq!(c.owner_timeout(), Duration::from_secs(10));
        assert!(c.allow().unwrap().permits("192.0.2.1".parse().unwrap()));
        assert_eq!(c.heartbeat_timeout(), Some(Duration::from_secs(2)));
        assert!(c.machine.scenario.unwrap().is_absolute());
    }

    #[test]
    fn a_postgres_url_takes_the_place_of_the_sqlite_file() {
        use crate::history::HistoryTarget;
        let base = "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n[history]\n";
        let dir = std::env::temp_dir().join("gateway.toml");
        let url = "postgres://gw:pw@db.factory:5432/history";
        let c = GatewayConfig::parse(&format!("{base}postgres = {url:?}\n"), &dir).unwrap();
        assert_eq!(c.history(), Some(HistoryTarget::Postgres(url.into())));
        let e = GatewayConfig::parse(&format!("{base}postgres = \"db.factory\"\n"), &dir)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("history.postgres") && e.contains("postgres://"),
            "{e}"
        );
        assert_eq!(
            HistoryTarget::Postgres(url.into()).display(),
            "postgres://gw:***@db.factory:5432/history"
        );
    }

    #[test]
    fn a_bare_file_name_anchors_relative_paths_in_the_current_folder() {
        let c = GatewayConfig::parse(
            "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n[history]\nsqlite = \"h.sqlite\"\n",
            Path::new("gateway.toml"),
        )
        .unwrap();
        assert_eq!(c.history.sqlite, Path::new("./h.sqlite"));
        assert_eq!(c.programs.folder, Path::new("./."));
    }

    #[test]
    fn history_timeouts_and_spool_are_checked_and_the_spool_has_a_home() {
        let base = "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n[history]\nsqlite = \"h.sqlite\"\n";
        let file = std::env::temp_dir().join("gateway.toml");
        for (extra, key) in [
            ("statement_timeout_ms = 0\n", "history.statement_timeout_ms"),
            (
                "connect_timeout_ms = 999999\n",
                "history.connect_timeout_ms",
            ),
            ("keepalive_s = 0\n", "history.keepalive_s"),
            ("spool = \"/nonexistent/h.spool\"\n", "history.spool"),
        ] {
            let e = GatewayConfig::parse(&format!("{base}{extra}"), &file)
                .unwrap_err()
                .to_string();
            assert!(e.contains(key), "{e}");
        }
        let c =
            GatewayConfig::parse(&format!("{base}statement_timeout_ms = 750\n"), &file).unwrap();
        assert_eq!(c.history_timeouts().statement, Duration::from_millis(750));
        if std::env::var_os("STATE_DIRECTORY").is_none() {
            assert_eq!(c.spool_path(), std::env::temp_dir().join("h.spool"));
        }
        let c = GatewayConfig::parse(&format!("{base}spool = \"s.spool\"\n"), &file).unwrap();
        assert_eq!(c.spool_path(), std::env::temp_dir().join("s.spool"));
    }

    #[test]
    fn the_web_face_listens_on_loopback_for_a_port_alone_and_alarms_are_checked() {
        let base = "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n";
        let c = parse(&format!("{base}[web]\nlisten = \"8080\"\n")).unwrap();
        assert_eq!(c.web_listen().unwrap(), Some(([127, 0, 0, 1], 8080).into()));
        let c = parse(&format!("{base}[web]\nlisten = \"0.0.0.0:8081\"\n")).unwrap();
        assert_eq!(c.web_listen().unwrap(), Some(([0, 0, 0, 0], 8081).into()));
        let dir = std::env::temp_dir().join("gateway.toml");
        let e = GatewayConfig::parse(
            &format!("{base}[history]\nsqlite = \"h.sqlite\"\nalarm_um = 0\n"),
            &dir,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("history.alarm_um") && e.contains("gateway.toml"),
            "{e}"
        );
    }

    #[test]
    fn unknown_key_is_refused_with_its_name() {
        let e = parse("[machine]\nscenario = \"s\"\nspeed = 1\n[programs]\nfolder = \".\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("gateway.toml") && e.contains("speed"), "{e}");
    }

    #[test]
    fn bad_values_name_the_key() {
        let base = "[machine]\nscenario = \"s\"\n[programs]\nfolder = \".\"\n";
        for (extra, key) in [
            ("[plc]\nword_order = \"middle\"\n", "plc.word_order"),
            ("[plc]\nlisten = \"localhost\"\n", "plc.listen"),
            ("[plc]\nint_scale = 0.5\n", "plc.int_scale"),
            ("[web]\nlisten = \"localhost\"\n", "web.listen"),
            (
                "[web]\nlisten = \"8080\"\nmax_connections = 0\n",
                "web.max_connections",
            ),
            ("[web]\nrequest_timeout_ms = 5\n", "web.request_timeout_ms"),
            (
                "[plc]\nmax_connections = 0\n",
                "plc.max_connections: 0 is outside 1..256",
            ),
            ("[plc]\nmax_connections = 257\n", "plc.max_connections: 257"),
            (
                "[plc]\nowner_timeout_ms = 10\n",
                "plc.owner_timeout_ms: 10 is outside 500..600000",
            ),
            ("[plc]\nallow = []\n", "plc.allow: an empty list"),
            (
                "[plc]\nallow = [\"10.0.0.0/8\", \"plc\"]\n",
                "plc.allow: \"plc\" is not an address",
            ),
            ("[plc]\nallow = \"10.0.0.5\"\n", "allow"),
        ] {
            let e = parse(&format!("{base}{extra}")).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains("gateway.toml"), "{e}");
        }
        let c = parse(&format!(
            "{base}[plc]\nallow = [\"10.0.1.0/24\"]\nmax_connections = 2\nowner_timeout_ms = 500\n"
        ))
        .unwrap();
        assert!(c.allow().unwrap().permits("10.0.1.7".parse().unwrap()));
        assert!(!c.allow().unwrap().permits("127.0.0.1".parse().unwrap()));
        assert_eq!(c.owner_timeout(), Duration::from_millis(500));
        let e = parse("[machine]\n[programs]\nfolder = \".\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("machine"), "{e}");
        let e = parse("[machine]\nscenario = \"s\"\n[programs]\nfolder = \"/nonexistent/x\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("programs.folder"), "{e}");
    }
}
