//! The machine description: axes and their drives, bus timing, kinematic chain. One
//! TOML file per machine under `configs/machines/`. Parsing is strict: an unknown key or
//! a value out of range is an error naming the file, the key and why, before anything
//! moves. The same file carries the probe table (`[[probe]]`) and the measuring cycles'
//! machine parameters (`[cycles]`): probebridge-cycles reads and validates those; hal
//! accepts exactly these two sections unread.

use crate::axis::Axis;
use serde::de::IgnoredAny;
use serde::Deserialize;
use std::path::{Path, PathBuf};

mod axis;
pub mod bounds;
mod bus;
mod error;
mod file;
mod kinematics;
mod spindle;

pub use crate::modbus::config::ModbusBusConfig;
pub use axis::AxisConfig;
pub use bus::{BusConfig, CanOpenBusConfig};
pub use error::{ConfigError, ConfigErrorKind};
pub use file::{read_config_text, MAX_CONFIG_BYTES};
pub use kinematics::KinematicsConfig;
pub use spindle::SpindleConfig;

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MachineConfig {
    pub name: String,
    #[serde(default)]
    pub description: String,
    #[serde(rename = "axis")]
    pub axes: Vec<AxisConfig>,
    #[serde(default)]
    pub bus: BusConfig,
    #[serde(default)]
    pub kinematics: KinematicsConfig,
    /// `[spindle]`: an orientable spindle's drive on the CANopen bus (a PLC on Modbus
    /// orients its spindle itself: `bus.spindle_orientation`).
    #[serde(default)]
    pub spindle: Option<SpindleConfig>,
    /// `[[probe]]`: the probe table, read and validated by probebridge-cycles.
    #[serde(rename = "probe", default)]
    pub probe_table: IgnoredAny,
    /// `[cycles]`: the measuring cycles' machine parameters, read and validated by
    /// probebridge-cycles.
    #[serde(rename = "cycles", default)]
    pub cycle_parameters: IgnoredAny,
    /// Where this configuration was read from (set by [`MachineConfig::load`]).
    #[serde(skip)]
    pub path: PathBuf,
}

impl MachineConfig {
    /// Parses and validates; `path` names the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut cfg: MachineConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        cfg.path = path.to_path_buf();
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn axis(&self, axis: Axis) -> Option<&AxisConfig> {
        self.axes.iter().find(|a| a.name == axis)
    }

    /// Mask of configured axes (bit = [`Axis::index`]).
    pub fn axis_mask(&self) -> u8 {
        self.axes.iter().fold(0, |m, a| m | 1 << a.name.index())
    }

    /// The CANopen bus section, when the machine is on CANopen.
    pub fn canopen_bus(&self) -> Option<&CanOpenBusConfig> {
        match &self.bus {
            BusConfig::CanOpen(b) => Some(b),
            BusConfig::Modbus(_) => None,
        }
    }

    /// [`MachineConfig::canopen_bus`], to change (tests, benchmarks).
    pub fn canopen_bus_mut(&mut self) -> Option<&mut CanOpenBusConfig> {
        match &mut self.bus {
            BusConfig::CanOpen(b) => Some(b),
            BusConfig::Modbus(_) => None,
        }
    }

    /// The CANopen bus settings, or the defaults for a machine on another bus (what a
    /// simulated CAN bus of that machine runs with).
    pub fn canopen_or_default(&self) -> CanOpenBusConfig {
        self.canopen_bus().cloned().unwrap_or_default()
    }

    /// The Modbus settings, when a PLC owns the axes.
    pub fn modbus_bus(&self) -> Option<&ModbusBusConfig> {
        match &self.bus {
            BusConfig::Modbus(b) => Some(b),
            BusConfig::CanOpen(_) => None,
        }
    }

    fn invalid(&self, key: impl Into<String>, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.clone(),
            key: key.into(),
            message: message.into(),
        }
    }

    /// Every software limit must fit the PLC's 32-bit counts.
    fn validate_modbus_reach(&self, m: &ModbusBusConfig) -> Result<(), ConfigError> {
        for a in &self.axes {
            let (per, key) = if a.name.is_rotary() {
                (m.counts_per_deg, "bus.counts_per_deg")
            } else {
                (m.counts_per_mm, "bus.counts_per_mm")
            };
            if a.min.abs().max(a.max.abs()) * per > i32::MAX as f64 {
                return Err(self.invalid(
                    key,
                    format!("axis {} limits overflow the PLC's 32-bit position", a.name),
                ));
            }
        }
        Ok(())
    }

    /// CANopen: a node ID per axis, each once, and timing the bus can keep.
    fn validate_canopen(&self, b: &CanOpenBusConfig) -> Result<(), ConfigError> {
        let mut seen_nodes = [false; 128];
        for (i, a) in self.axes.iter().enumerate() {
            let key = format!("axis[{i}] ({}).node", a.name);
            let Some(node) = a.node else {
                return Err(self.invalid(
                    key,
                    "missing: every axis of a CANopen machine names its drive's node ID (1..127)",
                ));
            };
            if !(1..=127).contains(&node) {
                return Err(self.invalid(key, format!("{node} is not a CANopen node ID (1..127)")));
            }
            if seen_nodes[node as usize] {
                return Err(self.invalid(key, format!("node {node} used by two axes")));
            }
            seen_nodes[node as usize] = true;
        }
        if !(10_000..=1_000_000).contains(&b.bitrate) {
            return Err(self.invalid(
                "bus.bitrate",
                format!(
                    "{} is not a CAN bit rate (10 kbit/s .. 1 Mbit/s)",
                    b.bitrate
                ),
            ));
        }
        if !(250..=100_000).contains(&b.sync_period_us) {
            return Err(self.invalid("bus.sync_period_us", "must be 250..100000"));
        }
        if b.heartbeat_producer_ms == 0 || b.heartbeat_timeout_ms <= b.heartbeat_producer_ms {
            return Err(self.invalid(
                "bus.heartbeat_timeout_ms",
                "must be longer than heartbeat_producer_ms, which must be > 0",
            ));
        }
        let (lo, hi) = bounds::SDO_TIMEOUT_MS;
        if !(lo..=hi).contains(&b.sdo_timeout_ms) {
            return Err(self.invalid(
                "bus.sdo_timeout_ms",
                format!(
                    "{} is outside {lo} .. {hi} ms (a drive answers an SDO within milliseconds; 0 would give up at once)",
                    b.sdo_timeout_ms
                ),
            ));
        }
        if !(1..=127).contains(&b.master_node) {
            return Err(self.invalid(
                "bus.master_node",
                format!("{} is not a CANopen node ID (1..127)", b.master_node),
            ));
        }
        if seen_nodes[b.master_node as usize] {
            return Err(self.invalid(
                "bus.master_node",
                format!(
                    "node {} is an axis's drive: the master needs its own node ID",
                    b.master_node
                ),
            ));
        }
        if let Some(s) = &self.spindle {
            if !(1..=127).contains(&s.node) {
                return Err(self.invalid(
                    "spindle.node",
                    format!("{} is not a CANopen node ID (1..127)", s.node),
                ));
            }
            if seen_nodes[s.node as usize] || s.node == b.master_node {
                return Err(self.invalid(
                    "spindle.node",
                    format!(
                        "node {} is already an axis's drive or the master: the spindle drive needs its own node ID",
                        s.node
                    ),
                ));
            }
            s.check().map_err(|(key, why)| self.invalid(key, why))?;
        }
        let most = u16::MAX / CanOpenBusConfig::MASTER_HEARTBEAT_CONSUMER_FACTOR;
        if b.master_heartbeat_ms > most {
            return Err(self.invalid(
                "bus.master_heartbeat_ms",
                format!(
                    "{} ms: at most {most} (the drives' consumer time, {} times it, is 16 bits of ms)",
                    b.master_heartbeat_ms,
                    CanOpenBusConfig::MASTER_HEARTBEAT_CONSUMER_FACTOR
                ),
            ));
        }
        if b.master_heartbeat_ms > 0 && u32::from(b.master_heartbeat_ms) * 1000 < b.sync_period_us {
            return Err(self.invalid(
                "bus.master_heartbeat_ms",
                "shorter than bus.sync_period_us: the master sends it with a SYNC",
            ));
        }
        if !(b.max_load_percent > 0.0 && b.max_load_percent <= 100.0) {
            return Err(self.invalid("bus.max_load_percent", "must be in (0, 100]"));
        }
        Ok(())
    }

    fn validate(&self) -> Result<(), ConfigError> {
        if self.axes.is_empty() {
            return Err(self.invalid("axis", "no axes configured"));
        }
        for lin in Axis::LINEAR {
            if self.axis(lin).is_none() {
                return Err(self.invalid("axis", format!("linear axis {lin} is missing")));
            }
        }
        let mut seen_axes = 0u8;
        for (i, a) in self.axes.iter().enumerate() {
            let key = |f: &str| format!("axis[{i}] ({}).{f}", a.name);
            if seen_axes & (1 << a.name.index()) != 0 {
                return Err(self.invalid(key("name"), "axis configured twice"));
            }
            seen_axes |= 1 << a.name.index();
            if !(a.increments_per_unit.is_finite() && a.increments_per_unit > 0.0) {
                return Err(self.invalid(key("increments_per_unit"), "must be > 0"));
            }
            if !(a.min.is_finite() && a.max.is_finite() && a.min < a.max) {
                return Err(self.invalid(
                    key("min"),
                    format!("limits {}..{} are not an interval", a.min, a.max),
                ));
            }
            // The drive position is an i32 of increments.
            let reach = a.min.abs().max(a.max.abs()) * a.increments_per_unit;
            if reach > i32::MAX as f64 {
                return Err(self.invalid(
                    key("increments_per_unit"),
                    "limits overflow the drive's 32-bit position",
                ));
            }
            for (field, v, (lo, hi), unit) in [
                ("max_feed", a.max_feed, bounds::MAX_FEED, "mm/min (deg/min)"),
                (
                    "max_acceleration",
                    a.max_acceleration,
                    bounds::MAX_ACCELERATION,
                    "mm/s^2 (deg/s^2)",
                ),
            ] {
                if !(lo..=hi).contains(&v) {
                    return Err(
                        self.invalid(key(field), format!("{v} is outside {lo} .. {hi} {unit}"))
                    );
                }
            }
            let (lo, hi) = bounds::HIRTH;
            if !(lo..=hi).contains(&a.hirth) || (a.hirth > 0.0 && !a.name.is_rotary()) {
                return Err(self.invalid(
                    key("hirth"),
                    format!(
                        "{}: a Hirth grid is {lo} .. {hi} deg (0 = none) and only for rotary axes",
                        a.hirth
                    ),
                ));
            }
        }
        match &self.bus {
            BusConfig::CanOpen(b) => self.validate_canopen(b)?,
            BusConfig::Modbus(m) => {
                m.validate()
                    .map_err(|e| self.invalid(format!("bus.{}", e.key), e.reason))?;
                self.validate_modbus_reach(m)?;
                if self.spindle.is_some() {
                    return Err(self.invalid(
                        "spindle",
                        "a [spindle] drive is on a CANopen bus; over Modbus the PLC orients the spindle (command 5): set spindle_orientation = true in [bus] instead",
                    ));
                }
            }
        }
        self.validate_kinematics()
    }

    /// The chains name each rotary axis once, on one side, each with a finite pivot
    /// within reach.
    fn validate_kinematics(&self) -> Result<(), ConfigError> {
        let k = &self.kinematics;
        for (side, list) in [("table", &k.table), ("head", &k.head)] {
            for (i, ax) in list.iter().enumerate() {
                if list[..i].contains(ax) {
                    return Err(self.invalid(
                        format!("kinematics.{side}"),
                        format!("{ax} is listed twice"),
                    ));
                }
                if side == "head" && k.table.contains(ax) {
                    return Err(self.invalid(
                        "kinematics.head",
                        format!(
                            "{ax} is in both the table and the head chain; an axis moves either the workpiece or the tool"
                        ),
                    ));
                }
                if !ax.is_rotary() {
                    return Err(self.invalid(
                        format!("kinematics.{side}"),
                        format!("{ax} is not a rotary axis"),
                    ));
                }
                if self.axis(*ax).is_none() {
                    return Err(self.invalid(
                        format!("kinematics.{side}"),
                        format!("{ax} has no [[axis]] entry"),
                    ));
                }
                if !k.pivot.contains_key(ax) {
                    return Err(self.invalid("kinematics.pivot", format!("no pivot for {ax}")));
                }
            }
        }
        let reach = bounds::PIVOT_MM;
        for (ax, p) in &k.pivot {
            if let Some(v) = p.iter().find(|v| !(-reach..=reach).contains(*v)) {
                return Err(self.invalid(
                    format!("kinematics.pivot.{ax}"),
                    format!("{v} is outside -{reach} .. {reach} mm (finite, within the machine)"),
                ));
            }
        }
        for a in &self.axes {
            if a.name.is_rotary() && !k.table.contains(&a.name) && !k.head.contains(&a.name) {
                return Err(self.invalid(
                    "kinematics",
                    format!(
                        "rotary axis {} is in neither the table nor the head chain",
                        a.name
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oversized_and_endless_files_are_refused_at_once() {
        let e = read_config_text(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("larger than 1048576 bytes"), "{e}");
        let big = std::env::temp_dir().join(format!("hal-big-{}.toml", std::process::id()));
        std::fs::write(&big, "# comment\n".repeat(120_000)).unwrap();
        let e = MachineConfig::load(&big).unwrap_err().to_string();
        let _ = std::fs::remove_file(&big);
        assert!(e.contains("hal-big") && e.contains("larger than"), "{e}");
    }

    const MINI: &str = r#"
name = "mini"
[[axis]]
name = "X"
node = 1
increments_per_unit = 10000.0
min = -100.0
max = 100.0
max_feed = 5000.0
max_acceleration = 1000.0
[[axis]]
name = "Y"
node = 2
increments_per_unit = 10000.0
min = -100.0
max = 100.0
max_feed = 5000.0
max_acceleration = 1000.0
[[axis]]
name = "Z"
node = 3
increments_per_unit = 10000.0
min = -100.0
max = 100.0
max_feed = 5000.0
max_acceleration = 1000.0
"#;

    #[test]
    fn parses_minimal() {
        let c = MachineConfig::parse(MINI, Path::new("mini.toml")).unwrap();
        assert_eq!(c.axis_mask(), 0b111);
        assert_eq!(c.canopen_bus().unwrap().sync_period_us, 2000);
    }

    /// Found by the fuzz target machine-toml (non-finite numbers accepted): a Hirth
    /// grid or a pivot of `nan`/`inf` is refused with its key.
    #[test]
    fn non_finite_hirth_and_pivot_are_refused() {
        let rotary = MINI.to_string()
            + "[[axis]]\nname = \"C\"\nnode = 4\nincrements_per_unit = 1000.0\nmin = -360.0\n\
               max = 360.0\nmax_feed = 5000.0\nmax_acceleration = 1000.0\nHIRTH\n\
               [kinematics]\ntable = [\"C\"]\n[kinematics.pivot]\nC = PIVOT\n";
        let ok = rotary
            .replace("HIRTH", "hirth = 1.0")
            .replace("PIVOT", "[0.0, 0.0, 0.0]");
        MachineConfig::parse(&ok, Path::new("m.toml")).unwrap();
        for (hirth, pivot, key) in [
            ("hirth = nan", "[0.0, 0.0, 0.0]", "axis[3] (C).hirth"),
            ("hirth = inf", "[0.0, 0.0, 0.0]", "axis[3] (C).hirth"),
            ("hirth = 1.0", "[nan, 0.0, 0.0]", "kinematics.pivot.C"),
            ("hirth = 1.0", "[0.0, 0.0, -inf]", "kinematics.pivot.C"),
        ] {
            let text = rotary.replace("HIRTH", hirth).replace("PIVOT", pivot);
            let e = MachineConfig::parse(&text, Path::new("m.toml")).unwrap_err();
            assert_eq!(e.kind(), ConfigErrorKind::Invalid, "{hirth} {pivot}");
            assert!(e.to_string().contains(key), "{hirth} {pivot}: {e}");
        }
    }

    #[test]
    fn unknown_key_is_named() {
        let e = MachineConfig::parse(
            &MINI.replace(
                "max_feed = 5000.0\nmax_acceleration = 1000.0\n[[axis]]\nname = \"Y\"",
                "max_fed = 1.0\n[[axis]]\nname = \"Y\"",
            ),
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("m.toml") && e.contains("max_fed"), "{e}");
    }

    #[test]
    fn a_canopen_axis_without_node_is_refused() {
        let e =
            MachineConfig::parse(&MINI.replace("node = 2\n", ""), Path::new("m.toml")).unwrap_err();
        assert_eq!(e.kind(), ConfigErrorKind::Invalid);
        let e = e.to_string();
        assert!(
            e.contains("m.toml") && e.contains("axis[1] (Y).node") && e.contains("missing"),
            "{e}"
        );
    }

    #[test]
    fn the_bus_names_its_kind() {
        let c = MachineConfig::parse(
            &format!("{MINI}[bus]\nkind = \"canopen\"\nsync_period_us = 1000\n"),
            Path::new("m.toml"),
        )
        .unwrap();
        assert_eq!(c.bus.kind(), "canopen");
        assert_eq!(c.canopen_bus().unwrap().sync_period_us, 1000);
        for bad in [
            "[bus]\nsync_period_us = 1000\n",
            "[bus]\nkind = \"profibus\"\n",
        ] {
            let e = MachineConfig::parse(&format!("{MINI}{bad}"), Path::new("m.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("m.toml") && (e.contains("kind") || e.contains("profibus")),
                "{e}"
            );
        }
    }

    #[test]
    fn probe_table_and_cycles_are_left_to_the_cycles_other_sections_refused() {
        let with =
            format!("{MINI}[[probe]]\nname = \"P\"\nanything = 1\n[cycles]\nmaxDevCalBall = 0.1\n");
        MachineConfig::parse(&with, Path::new("m.toml")).unwrap();
        let e = MachineConfig::parse(
            &format!("{MINI}[probes]\nname = \"P\"\n"),
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("m.toml") && e.contains("probes"), "{e}");
    }

    fn refused(text: &str) -> (String, String) {
        match MachineConfig::parse(text, Path::new("m.toml")).unwrap_err() {
            ConfigError::Invalid { path, key, message } => {
                assert_eq!(path, Path::new("m.toml"));
                (key, message)
            }
            e => panic!("not Invalid: {e}"),
        }
    }

    const ROTARY: &str = r#"
[[axis]]
name = "A"
node = 4
increments_per_unit = 1000.0
min = -120.0
max = 120.0
max_feed = 7200.0
max_acceleration = 720.0
[[axis]]
name = "C"
node = 5
increments_per_unit = 1000.0
min = -360.0
max = 360.0
max_feed = 7200.0
max_acceleration = 720.0
[kinematics]
table = ["A", "C"]
[kinematics.pivot]
A = [0.0, 0.0, 0.0]
C = [0.0, 0.0, 0.0]
"#;

    /// Values outside the plausible ranges (docs/configuration.md) are refused with
    /// the file, the key, the value and the range. On main before these bounds every
    /// one of these parsed (`1e-300 > 0`, a NaN compares false, 0 ms was taken).
    #[test]
    fn implausible_values_are_refused_with_key_and_range() {
        let with_rotary = format!("{MINI}{ROTARY}");
        MachineConfig::parse(&with_rotary, Path::new("m.toml")).unwrap();
        let cases: Vec<(String, &str, &str)> = vec![
            (
                MINI.replacen("max_acceleration = 1000.0", "max_acceleration = 1e-300", 1),
                "axis[0] (X).max_acceleration",
                "outside 10 .. 100000",
            ),
            (
                MINI.replacen("max_acceleration = 1000.0", "max_acceleration = inf", 1),
                "axis[0] (X).max_acceleration",
                "inf is outside",
            ),
            (
                MINI.replacen("max_feed = 5000.0", "max_feed = 0.001", 1),
                "axis[0] (X).max_feed",
                "outside 1 .. 200000",
            ),
            (
                with_rotary.replace("A = [0.0, 0.0, 0.0]", "A = [nan, 0.0, 0.0]"),
                "kinematics.pivot.A",
                "NaN is outside -10000 .. 10000 mm",
            ),
            (
                with_rotary.replace("C = [0.0, 0.0, 0.0]", "C = [0.0, 1e9, 0.0]"),
                "kinematics.pivot.C",
                "outside",
            ),
            (
                with_rotary.replace(
                    "table = [\"A\", \"C\"]",
                    "table = [\"A\", \"C\"]\nhead = [\"C\"]",
                ),
                "kinematics.head",
                "C is in both the table and the head chain",
            ),
            (
                with_rotary.replace("table = [\"A\", \"C\"]", "table = [\"A\", \"C\", \"A\"]"),
                "kinematics.table",
                "A is listed twice",
            ),
            (
                with_rotary.replace(
                    "max_acceleration = 720.0\n[kinematics]",
                    "max_acceleration = 720.0\nhirth = nan\n[kinematics]",
                ),
                "axis[4] (C).hirth",
                "NaN: a Hirth grid is 0 .. 45 deg",
            ),
            (
                format!("{MINI}[bus]\nkind = \"canopen\"\nsdo_timeout_ms = 0\n"),
                "bus.sdo_timeout_ms",
                "0 is outside 10 .. 10000 ms",
            ),
        ];
        for (text, key, why) in cases {
            let (k, m) = refused(&text);
            assert_eq!(k, key, "{m}");
            assert!(m.contains(why), "{key}: {m}");
        }
    }

    #[test]
    fn duplicate_node_is_refused() {
        let e = MachineConfig::parse(&MINI.replace("node = 2", "node = 1"), Path::new("m.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("axis[1] (Y).node") && e.contains("node 1 used by two axes"),
            "{e}"
        );
    }

    #[test]
    fn the_master_heartbeat_has_defaults_and_is_validated() {
        let c = MachineConfig::parse(MINI, Path::new("m.toml")).unwrap();
        let b = c.canopen_bus().unwrap();
        assert_eq!((b.master_node, b.master_heartbeat_ms), (127, 100));
        // 0x1016:1 = node 127 << 16 | 3 x 100 ms.
        assert_eq!(b.master_heartbeat_consumer_entry(), 0x007F_012C);
        let off = MachineConfig::parse(
            &format!("{MINI}[bus]\nkind = \"canopen\"\nmaster_heartbeat_ms = 0\n"),
            Path::new("m.toml"),
        )
        .unwrap();
        assert_eq!(
            off.canopen_bus().unwrap().master_heartbeat_consumer_entry(),
            0
        );
        for (bad, key, why) in [
            (
                "master_node = 0",
                "bus.master_node",
                "not a CANopen node ID",
            ),
            (
                "master_node = 128",
                "bus.master_node",
                "not a CANopen node ID",
            ),
            (
                "master_node = 2",
                "bus.master_node",
                "node 2 is an axis's drive",
            ),
            (
                "master_heartbeat_ms = 30000",
                "bus.master_heartbeat_ms",
                "at most 21845",
            ),
            (
                "master_heartbeat_ms = 1",
                "bus.master_heartbeat_ms",
                "shorter than bus.sync_period_us",
            ),
        ] {
            let e = MachineConfig::parse(
                &format!("{MINI}[bus]\nkind = \"canopen\"\n{bad}\n"),
                Path::new("m.toml"),
            )
            .unwrap_err();
            assert_eq!(e.kind(), ConfigErrorKind::Invalid);
            let e = e.to_string();
            assert!(
                e.contains("m.toml") && e.contains(key) && e.contains(why),
                "{bad}: {e}"
            );
        }
    }

    const SPINDLE: &str = "[spindle]\nnode = 6\nincrements_per_degree = 1000.0\n";

    #[test]
    fn a_spindle_drive_has_defaults_and_is_validated() {
        let c = MachineConfig::parse(&format!("{MINI}{SPINDLE}"), Path::new("m.toml")).unwrap();
        let s = c.spindle.as_ref().unwrap();
        assert_eq!(
            (s.node, s.orient_rpm, s.orient_acceleration),
            (6, 300.0, 36000.0)
        );
        // 300 rpm = 1800 deg/s; 36000 deg/s² at 1000 increments per degree.
        assert_eq!(
            (s.profile_velocity(), s.profile_acceleration()),
            (1_800_000, 36_000_000)
        );
        for (text, key, why) in [
            (
                format!("{MINI}{}", SPINDLE.replace("node = 6", "node = 2")),
                "spindle.node",
                "node 2 is already an axis's drive or the master",
            ),
            (
                format!("{MINI}{}", SPINDLE.replace("node = 6", "node = 127")),
                "spindle.node",
                "node 127 is already an axis's drive or the master",
            ),
            (
                format!("{MINI}{}", SPINDLE.replace("node = 6", "node = 0")),
                "spindle.node",
                "0 is not a CANopen node ID",
            ),
            (
                format!("{MINI}{}", SPINDLE.replace("1000.0", "0.0")),
                "spindle.increments_per_degree",
                "must be > 0",
            ),
            (
                format!("{MINI}{}", SPINDLE.replace("1000.0", "1e7")),
                "spindle.increments_per_degree",
                "overflows the drive's 32-bit position",
            ),
            (
                format!("{MINI}{SPINDLE}orient_rpm = nan\n"),
                "spindle.orient_rpm",
                "outside (0, 10000] rpm",
            ),
            (
                format!("{MINI}{SPINDLE}orient_acceleration = -1.0\n"),
                "spindle.orient_acceleration",
                "is not a profile acceleration",
            ),
            (
                // The shipped Modbus machine: its PLC orients the spindle.
                format!(
                    "{}\n{SPINDLE}",
                    std::fs::read_to_string(
                        Path::new(env!("CARGO_MANIFEST_DIR"))
                            .join("../configs/machines/table-ac-modbus.toml")
                    )
                    .unwrap()
                ),
                "spindle",
                "set spindle_orientation = true in [bus] instead",
            ),
        ] {
            let (k, m) = refused(&text);
            assert_eq!(k, key, "{m}");
            assert!(m.contains(why), "{key}: {m}");
        }
    }
}
