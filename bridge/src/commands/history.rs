//! `probebridge history`: the recorded runs of a gateway, as lines or JSON.

use crate::history::trend::{trend_pages, Alarm};
use crate::history::{time::parse_since, to_text, Filter, History, HistoryTarget, RunRow};
use crate::serve::config::GatewayConfig;
use std::io::Write;
use std::path::PathBuf;

pub struct HistoryArgs {
    /// The SQLite file or a `postgres://` URL; default: the gateway configuration's
    /// history.
    pub db: Option<PathBuf>,
    pub config: PathBuf,
    pub machine: Option<String>,
    pub since: Option<String>,
    pub json: bool,
    /// Write the trend page here.
    pub html: Option<PathBuf>,
    /// The trend page's alarm thresholds (default: the configuration's, else 5 µm and
    /// 10 arcsec).
    pub alarm_um: Option<f64>,
    pub alarm_arcsec: Option<f64>,
}

pub fn run(args: &HistoryArgs) -> Result<(), String> {
    let since = args.since.as_deref().map(parse_since).transpose()?;
    for (flag, v) in [
        ("--alarm-um", args.alarm_um),
        ("--alarm-arcsec", args.alarm_arcsec),
    ] {
        if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(format!("{flag}: expected a number above 0"));
        }
    }
    let mut alarm = Alarm::default();
    let target = match &args.db {
        Some(p) => HistoryTarget::from_arg(p),
        None => {
            let cfg = GatewayConfig::load(&args.config).map_err(|e| needs_a_history(&e))?;
            alarm = cfg.alarm();
            cfg.history().ok_or_else(|| {
                needs_a_history(&format!(
                    "{}: history.enabled is false: no history",
                    args.config.display()
                ))
            })?
        }
    };
    alarm.um = args.alarm_um.unwrap_or(alarm.um);
    alarm.arcsec = args.alarm_arcsec.unwrap_or(alarm.arcsec);
    if let HistoryTarget::Sqlite(db) = &target {
        if !db.is_file() {
            return Err(format!("{}: no history recorded there", db.display()));
        }
    }
    let mut h = History::open(&target).map_err(|e| e.to_string())?;
    let runs = h
        .list(&Filter {
            machine: args.machine.clone(),
            since,
        })
        .map_err(|e| e.to_string())?;
    if let Some(path) = &args.html {
        write_trend(path, &runs, &alarm)?;
    }
    // The listing is this command's result: a failed write to stdout is an error.
    let text = if args.json {
        serde_json::to_string_pretty(&runs).map_err(|e| e.to_string())? + "\n"
    } else if args.html.is_none() {
        to_text(&runs)
    } else {
        return Ok(());
    };
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| format!("cannot write the history to stdout: {e}"))
}

/// Why no history was found, with what the command needs: without `--db` it reads the
/// gateway configuration, which a clone or a fresh machine does not have.
fn needs_a_history(why: &dyn std::fmt::Display) -> String {
    format!(
        "{why}\nhistory needs the recorded runs: --db FILE (the SQLite file or a postgres:// \
         URL that `run --history` or `serve` wrote), or --config GATEWAY.toml with history enabled"
    )
}

/// The trend page at `path`; several machines: `path` is their index and each
/// machine's page is `STEM-N.html` beside it. All checked before any is written.
fn write_trend(path: &std::path::Path, runs: &[RunRow], alarm: &Alarm) -> Result<(), String> {
    let stem = path
        .file_stem()
        .map_or("trend".into(), |s| s.to_string_lossy().into_owned());
    let mut pages = trend_pages(runs, alarm, &stem);
    // The first page is the file asked for, whatever its extension.
    let mut files = vec![(path.to_path_buf(), pages.remove(0).1)];
    for (name, html) in pages {
        files.push((path.with_file_name(name), html));
    }
    for (p, _) in &files {
        crate::output::check_output(Some(p))?;
    }
    for (p, html) in &files {
        crate::output::write_atomic(p, html.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(config: PathBuf) -> HistoryArgs {
        HistoryArgs {
            db: None,
            config,
            machine: None,
            since: None,
            json: false,
            html: None,
            alarm_um: None,
            alarm_arcsec: None,
        }
    }

    #[test]
    fn without_db_or_a_readable_config_it_says_what_it_needs() {
        let e = run(&args(PathBuf::from(
            "/nonexistent/probebridge/gateway.toml",
        )))
        .unwrap_err();
        assert!(e.contains("/nonexistent/probebridge/gateway.toml"), "{e}");
        assert!(e.contains("--db FILE"), "{e}");
        assert!(e.contains("--config"), "{e}");
    }
}
