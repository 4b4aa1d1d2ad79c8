//! The machine's preset table, as the TNC keeps it: numbered rows, each a datum in
//! machine coordinates (X/Y/Z, mm, and where the machine has them the rotary offsets
//! A/B/C, deg), and which row is active. It lives beside the machine configuration as
//! `<machine>.presets.toml`:
//!
//! ```toml
//! machine = "table-ac"
//! active = 1
//!
//! [[preset]]
//! number = 0
//! X = 0.0
//! Y = 0.0
//! Z = 0.0
//!
//! [[preset]]
//! number = 1
//! X = 50.0
//! Y = -30.0
//! Z = 80.0
//! ```
//!
//! A machine without the file has the one row 0 at the machine origin, active. Cycle
//! 247 activates a row in a program; cycle 451 with Q431 = 1..3 overwrites the active
//! row with the sphere centre. Every write is atomic and keeps the replaced file as
//! `<file>.prev` ([`hal::atomic_write::write_atomic_keeping_previous`]).

use hal::atomic_write::{write_atomic_keeping_previous, WriteError};
use hal::config::{ConfigError, MachineConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One row: the datum in machine coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    pub number: u32,
    #[serde(rename = "X")]
    pub x: f64,
    #[serde(rename = "Y")]
    pub y: f64,
    #[serde(rename = "Z")]
    pub z: f64,
    /// Rotary offsets, deg (only for rotary axes the machine has).
    #[serde(rename = "A", default, skip_serializing_if = "Option::is_none")]
    pub a: Option<f64>,
    #[serde(rename = "B", default, skip_serializing_if = "Option::is_none")]
    pub b: Option<f64>,
    #[serde(rename = "C", default, skip_serializing_if = "Option::is_none")]
    pub c: Option<f64>,
}

impl Preset {
    /// A row at the machine origin.
    pub fn origin(number: u32) -> Self {
        Preset {
            number,
            x: 0.0,
            y: 0.0,
            z: 0.0,
            a: None,
            b: None,
            c: None,
        }
    }

    pub fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }

    /// The rotary offset of `axis` (0 when the row has none).
    pub fn rotary(&self, axis: hal::Axis) -> f64 {
        match axis {
            hal::Axis::A => self.a,
            hal::Axis::B => self.b,
            hal::Axis::C => self.c,
            _ => None,
        }
        .unwrap_or(0.0)
    }
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct FileFormat {
    machine: String,
    active: u32,
    #[serde(rename = "preset", default)]
    rows: Vec<Preset>,
}

/// The preset table of a machine and its file.
#[derive(Clone, Debug, PartialEq)]
pub struct PresetTable {
    pub machine: String,
    /// Number of the active row (always a row of the table).
    pub active: u32,
    /// Rows by ascending number, numbers unique.
    pub rows: Vec<Preset>,
    /// Where it is read from and written to.
    pub path: PathBuf,
}

impl PresetTable {
    /// `<dir of cfg.path>/<cfg.name>.presets.toml`.
    pub fn default_path(cfg: &MachineConfig) -> PathBuf {
        let dir = cfg.path.parent().unwrap_or(Path::new("."));
        dir.join(format!("{}.presets.toml", cfg.name))
    }

    /// The table of a machine without a preset file: row 0 at the origin, active.
    pub fn origin(cfg: &MachineConfig, path: PathBuf) -> Self {
        PresetTable {
            machine: cfg.name.clone(),
            active: 0,
            rows: vec![Preset::origin(0)],
            path,
        }
    }

    /// Reads `path`; an absent file is [`PresetTable::origin`].
    pub fn load(path: &Path, cfg: &MachineConfig) -> Result<Self, ConfigError> {
        match std::fs::read_to_string(path) {
            Ok(text) => Self::parse(&text, path, cfg),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                Ok(Self::origin(cfg, path.to_path_buf()))
            }
            Err(source) => Err(ConfigError::Read {
                path: path.to_path_buf(),
                source,
            }),
        }
    }

    /// Parses and validates: the machine's name, unique row numbers, finite values,
    /// rotary offsets only of axes the machine has, an active row that exists.
    pub fn parse(text: &str, path: &Path, cfg: &MachineConfig) -> Result<Self, ConfigError> {
        let f: FileFormat = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let invalid = |key: String, message: String| ConfigError::Invalid {
            path: path.to_path_buf(),
            key,
            message,
        };
        if f.machine != cfg.name {
            return Err(invalid(
                "machine".into(),
                format!(
                    "written for machine {:?}, but the machine is {:?}",
                    f.machine, cfg.name
                ),
            ));
        }
        let mut rows = f.rows;
        for (i, r) in rows.iter().enumerate() {
            let key = |k: &str| format!("preset[{i}] (number {}).{k}", r.number);
            for (k, v) in [("X", Some(r.x)), ("Y", Some(r.y)), ("Z", Some(r.z))]
                .into_iter()
                .chain([("A", r.a), ("B", r.b), ("C", r.c)])
            {
                let Some(v) = v else { continue };
                if !v.is_finite() {
                    return Err(invalid(key(k), "not a finite number".into()));
                }
                if k.len() == 1 && "ABC".contains(k) {
                    let axis = hal::Axis::from_name(k).expect("rotary name");
                    if cfg.axis(axis).is_none() {
                        return Err(invalid(
                            key(k),
                            format!("machine {} has no {k} axis", cfg.name),
                        ));
                    }
                }
            }
            if let Some(j) = rows[..i].iter().position(|o| o.number == r.number) {
                return Err(invalid(
                    key("number"),
                    format!("number {} is also row preset[{j}]", r.number),
                ));
            }
        }
        rows.sort_by_key(|r| r.number);
        let table = PresetTable {
            machine: f.machine,
            active: f.active,
            rows,
            path: path.to_path_buf(),
        };
        if table.row(f.active).is_none() {
            return Err(invalid(
                "active".into(),
                format!("no row number {} (rows: {})", f.active, table.numbers()),
            ));
        }
        Ok(table)
    }

    pub fn row(&self, number: u32) -> Option<&Preset> {
        self.rows.iter().find(|r| r.number == number)
    }

    /// The active row.
    pub fn active_row(&self) -> Preset {
        self.row(self.active)
            .copied()
            .unwrap_or(Preset::origin(self.active))
    }

    /// The row numbers, for messages: "0, 1, 5".
    pub fn numbers(&self) -> String {
        self.rows
            .iter()
            .map(|r| r.number.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Makes row `number` active; `Err` names the rows there are.
    pub fn activate(&mut self, number: u32) -> Result<(), String> {
        if self.row(number).is_none() {
            return Err(format!(
                "preset {number} is not in the preset table {} (rows: {})",
                self.path.display(),
                self.numbers()
            ));
        }
        self.active = number;
        Ok(())
    }

    /// Sets X/Y/Z of the active row (its rotary offsets stay).
    pub fn set_active_xyz(&mut self, xyz: [f64; 3]) {
        let active = self.active;
        match self.rows.iter_mut().find(|r| r.number == active) {
            Some(r) => [r.x, r.y, r.z] = xyz,
            None => {
                let mut r = Preset::origin(active);
                [r.x, r.y, r.z] = xyz;
                self.rows.push(r);
                self.rows.sort_by_key(|r| r.number);
            }
        }
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        let f = FileFormat {
            machine: self.machine.clone(),
            active: self.active,
            rows: self.rows.clone(),
        };
        toml::to_string(&f).expect("a preset table serialises")
    }

    /// Writes the table to its path atomically, keeping the replaced file as `.prev`.
    /// The file's comments stay: the values of the rows that changed are replaced in
    /// the old text ([`PresetTable::rewrite`]).
    pub fn write(&self) -> Result<(), WriteError> {
        let text = match std::fs::read_to_string(&self.path) {
            Ok(old) => self.rewrite(&old),
            Err(_) => self.to_toml(),
        };
        write_atomic_keeping_previous(&self.path, text.as_bytes())
    }

    /// Writes row `number` of this table into the file as it is now (the other rows
    /// and its `active` as they are there: cycle 247 activates a row for the program
    /// that runs, not for the next one), atomically, keeping `.prev` and comments.
    pub fn write_row(&self, number: u32, cfg: &MachineConfig) -> Result<(), WriteError> {
        let Some(row) = self.row(number).copied() else {
            return self.write();
        };
        let mut file = match Self::load(&self.path, cfg) {
            Ok(t) => t,
            // An unreadable file is replaced by this table (its `.prev` keeps it).
            Err(_) => return self.write(),
        };
        match file.rows.iter_mut().find(|r| r.number == number) {
            Some(r) => *r = row,
            None => {
                file.rows.push(row);
                file.rows.sort_by_key(|r| r.number);
            }
        }
        file.write()
    }

    /// The table as text, written into `old` (the file as it is): the `active` line and
    /// each row's values replaced where they stand, new rows and offsets appended,
    /// every comment and blank line kept. Where the old text cannot be followed (a
    /// layout this does not recognise), its leading comment block above the freshly
    /// serialised table. Either way the result parses back to this table.
    pub fn rewrite(&self, old: &str) -> String {
        if let Some(t) = self.rewrite_in_place(old) {
            return t;
        }
        let header: String = old
            .lines()
            .take_while(|l| l.trim().is_empty() || l.trim_start().starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect();
        format!("{header}{}", self.to_toml())
    }

    fn rewrite_in_place(&self, old: &str) -> Option<String> {
        // `key = value  # comment` -> the key, and the line with the value replaced.
        fn key_of(line: &str) -> Option<&str> {
            let (k, _) = line.split_once('=')?;
            let k = k.trim();
            (!k.is_empty() && !k.starts_with('#')).then_some(k)
        }
        fn with_value(line: &str, value: &str) -> String {
            let (k, rest) = line.split_once('=').expect("a key line");
            let comment = rest.find('#').map(|i| &rest[i..]).unwrap_or("");
            let sep = if comment.is_empty() { "" } else { " " };
            format!("{k}= {value}{sep}{comment}")
        }
        let value = |r: &Preset, k: &str| -> Option<f64> {
            match k {
                "X" => Some(r.x),
                "Y" => Some(r.y),
                "Z" => Some(r.z),
                "A" => r.a,
                "B" => r.b,
                "C" => r.c,
                _ => None,
            }
        };
        // The header, then one chunk per [[preset]].
        let mut chunks: Vec<Vec<String>> = vec![Vec::new()];
        for line in old.lines() {
            if line.trim() == "[[preset]]" {
                chunks.push(Vec::new());
            }
            chunks.last_mut().expect("a chunk").push(line.to_string());
        }
        let mut out = String::new();
        for line in &chunks[0] {
            match key_of(line) {
                Some("active") => out.push_str(&with_value(line, &self.active.to_string())),
                Some("machine") | None => out.push_str(line),
                Some(_) => return None,
            }
            out.push('\n');
        }
        let mut seen = Vec::new();
        for chunk in &chunks[1..] {
            let number: u32 = chunk
                .iter()
                .find(|l| key_of(l) == Some("number"))
                .and_then(|l| l.split_once('=')?.1.split('#').next()?.trim().parse().ok())?;
            let row = self.row(number)?;
            seen.push(number);
            let mut written = Vec::new();
            let mut lines = Vec::new();
            for line in chunk {
                match key_of(line) {
                    Some(k) if k.len() == 1 && "XYZABC".contains(k) => {
                        let v = value(row, k)?;
                        written.push(k.to_string());
                        lines.push(with_value(line, &format!("{v:?}")));
                    }
                    _ => lines.push(line.clone()),
                }
            }
            // Offsets the row has gained: after its last key line.
            let last_key = lines.iter().rposition(|l| key_of(l).is_some())?;
            let gained: Vec<String> = ["X", "Y", "Z", "A", "B", "C"]
                .iter()
                .filter(|k| !written.iter().any(|w| w == *k))
                .filter_map(|k| value(row, k).map(|v| format!("{k} = {v:?}")))
                .collect();
            lines.splice(last_key + 1..last_key + 1, gained);
            for l in lines {
                out.push_str(&l);
                out.push('\n');
            }
        }
        for r in self.rows.iter().filter(|r| !seen.contains(&r.number)) {
            out.push_str(&format!("\n[[preset]]\nnumber = {}\n", r.number));
            for k in ["X", "Y", "Z", "A", "B", "C"] {
                if let Some(v) = value(r, k) {
                    out.push_str(&format!("{k} = {v:?}\n"));
                }
            }
        }
        // Only a text that reads back as this very table.
        let back: FileFormat = toml::from_str(&out).ok()?;
        let mut rows = back.rows;
        rows.sort_by_key(|r| r.number);
        (back.machine == self.machine && back.active == self.active && rows == self.rows)
            .then_some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine() -> MachineConfig {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        MachineConfig::load(&path).unwrap()
    }

    #[test]
    fn reads_writes_and_refuses_with_key_and_reason() {
        let cfg = machine();
        let dir = std::env::temp_dir().join(format!("pb-presets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("table-ac.presets.toml");
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(hal::atomic_write::previous_path(&path));
        let absent = PresetTable::load(&path, &cfg).unwrap();
        assert_eq!((absent.active, absent.numbers()), (0, "0".to_string()));

        let text = "machine = \"table-ac\"\nactive = 1\n[[preset]]\nnumber = 1\nX = 50.0\nY = -30.0\nZ = 80.0\nC = 12.5\n[[preset]]\nnumber = 0\nX = 0.0\nY = 0.0\nZ = 0.0\n";
        let mut t = PresetTable::parse(text, &path, &cfg).unwrap();
        assert_eq!(t.active_row().xyz(), [50.0, -30.0, 80.0]);
        assert_eq!(t.active_row().rotary(hal::Axis::C), 12.5);
        assert_eq!(t.numbers(), "0, 1");
        t.write().unwrap();
        assert_eq!(PresetTable::load(&path, &cfg).unwrap(), t);
        t.set_active_xyz([1.0, 2.0, 3.0]);
        t.write().unwrap();
        let prev = std::fs::read_to_string(hal::atomic_write::previous_path(&path)).unwrap();
        assert!(prev.contains("50.0"), "{prev}");
        assert_eq!(
            PresetTable::load(&path, &cfg).unwrap().active_row().xyz(),
            [1.0, 2.0, 3.0]
        );
        let e = t.activate(7).unwrap_err();
        assert!(e.contains("preset 7") && e.contains("rows: 0, 1"), "{e}");

        for (bad, key, why) in [
            (
                text.replace("active = 1", "active = 4"),
                "active",
                "no row number 4",
            ),
            (
                text.replace("number = 0", "number = 1"),
                "preset[1] (number 1).number",
                "also row preset[0]",
            ),
            (
                text.replace("C = 12.5", "B = 1.0"),
                "preset[0] (number 1).B",
                "no B axis",
            ),
            (
                text.replace("\"table-ac\"", "\"other\""),
                "machine",
                "written for machine",
            ),
        ] {
            let e = PresetTable::parse(&bad, &path, &cfg).unwrap_err();
            let s = e.to_string();
            assert!(
                s.contains(&path.display().to_string()) && s.contains(key) && s.contains(why),
                "{s}"
            );
            assert_eq!(e.kind(), hal::config::ConfigErrorKind::Invalid);
        }
        let e = PresetTable::parse(&text.replace("X = 50.0", "X = 50.0\nQ = 1"), &path, &cfg)
            .unwrap_err();
        assert_eq!(e.kind(), hal::config::ConfigErrorKind::Parse, "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A rewritten table keeps its comments: the shipped table's header, a comment
    /// beside a value, a row's own comment; values change where they stand.
    #[test]
    fn a_rewrite_keeps_the_comments() {
        let cfg = machine();
        let shipped = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.presets.toml"),
        )
        .unwrap();
        let path = PathBuf::from("table-ac.presets.toml");
        for (old, set, row) in [
            (shipped.clone(), [12.5, -7.25, 99.0], 0),
            (shipped.clone(), [1e-5, 0.0, -3.0], 1),
            (
                "# mine\nmachine = \"table-ac\" # the name\nactive = 0 # row\n\n[[preset]]\n# the origin\nnumber = 0\nX = 0.0 # x\nY = 0.0\nZ = 0.0\n".to_string(),
                [4.0, 5.0, 6.0],
                0,
            ),
        ] {
            let mut t = PresetTable::parse(&old, &path, &cfg).unwrap();
            t.activate(row).unwrap();
            t.set_active_xyz(set);
            let new = t.rewrite(&old);
            for comment in old.lines().filter(|l| l.contains('#')) {
                let c = &comment[comment.find('#').unwrap()..];
                assert!(new.contains(c), "{c:?} lost:\n{new}");
            }
            assert_eq!(PresetTable::parse(&new, &path, &cfg).unwrap(), t, "{new}");
        }
        // A row that gains a rotary offset, and a new row.
        let mut t = PresetTable::parse(&shipped, &path, &cfg).unwrap();
        t.rows[1].c = Some(2.5);
        let mut r = Preset::origin(5);
        r.x = 7.0;
        t.rows.push(r);
        let new = t.rewrite(&shipped);
        assert!(new.starts_with("# The preset table"), "{new}");
        assert_eq!(PresetTable::parse(&new, &path, &cfg).unwrap(), t, "{new}");
    }
}
