//! The files a machine remembers between runs, in its folder of the state directory
//! ([`crate::state_dir`]): `<state>/<machine>/<machine>.presets.toml`,
//! `<machine>.kinematics.toml` (its `.prev`), `<machine>.kinematics.saved/` (cycle
//! 450), `<machine>.probes.toml` (the probes' calibration rows, cycle 460), and the
//! protocols (`protocols/`). The same layout for the CLI and `serve`.
//! A file missing there is seeded from the shipped one beside the machine
//! configuration (copied as it is, comments and all) the first time a command that may
//! write it runs; `check` only reads (the state's file, else the shipped one).
//! `--presets` / `--kinematics` name other files and win.

use cycles::kinematics_file::ActiveKinematics;
use cycles::preset_table::PresetTable;
use cycles::probe_table::probes_file::ProbeCalibrations;
use hal::config::MachineConfig;
use std::path::{Path, PathBuf};

/// Where the preset table, the active kinematics and the protocols of one run are.
#[derive(Clone, Debug)]
pub struct MachineFiles {
    pub presets: PathBuf,
    pub kinematics: PathBuf,
    /// The probes' calibration rows (cycle 460 writes them; 431, 444, 451 read them).
    pub probes: PathBuf,
    /// The machine's state folder (protocols go to `protocols/` below it by default).
    pub dir: PathBuf,
    /// What to tell the user: each file read, and where it was seeded from.
    pub notes: Vec<String>,
}

/// The machine's files: `presets` / `kinematics` when given, else in the machine's
/// folder below `state_root` (`--state-dir`, resolved by [`crate::state_dir`]).
/// `seed`: copy a shipped file there when the state has none (commands that may
/// write); without it a missing state file is read from the shipped one.
pub fn machine_files(
    cfg: &MachineConfig,
    state_root: Option<&Path>,
    presets: Option<&Path>,
    kinematics: Option<&Path>,
    seed: bool,
) -> Result<MachineFiles, String> {
    let root = crate::state_dir::state_dir(state_root)?;
    if cfg.name.is_empty() || cfg.name.contains(['/', '\\']) || cfg.name.starts_with('.') {
        return Err(format!(
            "machine name {:?} cannot name a folder of the state directory",
            cfg.name
        ));
    }
    let dir = root.join(&cfg.name);
    if seed {
        std::fs::create_dir_all(&dir)
            .map_err(|e| format!("state directory {}: {e}", dir.display()))?;
    }
    let mut notes = Vec::new();
    let mut pick =
        |given: Option<&Path>, shipped: PathBuf, what: &str| -> Result<PathBuf, String> {
            if let Some(p) = given {
                notes.push(format!("{what}: {} (given)", p.display()));
                return Ok(p.to_path_buf());
            }
            let state = dir.join(shipped.file_name().expect("a file name"));
            if state.exists() {
                notes.push(format!("{what}: {} (machine state)", state.display()));
                return Ok(state);
            }
            if !shipped.is_file() {
                notes.push(format!(
                    "{what}: {} (none yet: {})",
                    state.display(),
                    match what {
                        "presets" => "row 0 at the machine origin",
                        "probes" => "no calibration rows: every probe as [[probe]] gives it",
                        _ => "the nominal kinematics",
                    }
                ));
                return Ok(state);
            }
            if seed {
                std::fs::copy(&shipped, &state).map_err(|e| {
                    format!(
                        "cannot seed {} from {}: {e}",
                        state.display(),
                        shipped.display()
                    )
                })?;
                notes.push(format!(
                    "{what}: {} (machine state, seeded from {})",
                    state.display(),
                    shipped.display()
                ));
                Ok(state)
            } else {
                notes.push(format!(
                    "{what}: {} (shipped; the machine state has none yet)",
                    shipped.display()
                ));
                Ok(shipped)
            }
        };
    let presets = pick(presets, PresetTable::default_path(cfg), "presets")?;
    let kinematics = pick(
        kinematics,
        ActiveKinematics::default_path(cfg),
        "kinematics",
    )?;
    let probes = pick(None, ProbeCalibrations::default_path(cfg), "probes")?;
    Ok(MachineFiles {
        presets,
        kinematics,
        probes,
        dir,
        notes,
    })
}

/// The contents of the state files before a run, to say afterwards which were written.
pub struct Snapshot(Vec<(PathBuf, Option<Vec<u8>>)>);

impl MachineFiles {
    /// The saved kinematics folder of cycle 450 (beside the active file).
    fn saved_dir(&self) -> PathBuf {
        let stem = self
            .kinematics
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.kinematics.with_file_name(format!("{stem}.saved"))
    }

    fn watched(&self) -> Vec<PathBuf> {
        let mut v = vec![
            self.presets.clone(),
            self.kinematics.clone(),
            self.probes.clone(),
        ];
        if let Ok(rd) = std::fs::read_dir(self.saved_dir()) {
            v.extend(rd.flatten().map(|e| e.path()));
        }
        v
    }

    pub fn snapshot(&self) -> Snapshot {
        Snapshot(
            self.watched()
                .into_iter()
                .map(|p| {
                    let b = std::fs::read(&p).ok();
                    (p, b)
                })
                .collect(),
        )
    }

    /// "written: FILE" for each state file whose contents changed since `before`.
    pub fn written_since(&self, before: &Snapshot) -> Vec<String> {
        let mut out = Vec::new();
        for p in self.watched() {
            let now = std::fs::read(&p).ok();
            let was = before
                .0
                .iter()
                .find(|(q, _)| *q == p)
                .and_then(|(_, b)| b.clone());
            if now != was {
                out.push(format!("written: {}", p.display()));
            }
        }
        out
    }

    /// Where protocols go without `--out`: `protocols/` in the machine's state folder
    /// (never next to a shipped program in `configs/`).
    pub fn protocols_dir(&self) -> PathBuf {
        self.dir.join("protocols")
    }
}
