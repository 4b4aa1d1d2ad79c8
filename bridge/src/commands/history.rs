//! `probebridge history`: the recorded runs of a gateway, as lines or JSON.

use crate::history::{time::parse_since, to_text, Filter, History, HistoryTarget};
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
}

pub fn run(args: &HistoryArgs) -> Result<(), String> {
    let since = args.since.as_deref().map(parse_since).transpose()?;
    let target = match &args.db {
        Some(p) => HistoryTarget::from_arg(p),
        None => {
            let cfg = GatewayConfig::load(&args.config).map_err(|e| e.to_string())?;
            cfg.history().ok_or_else(|| {
                format!(
                    "{}: history.enabled is false: no history",
                    args.config.display()
                )
            })?
        }
    };
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
        crate::output::check_output(Some(path))?;
        crate::output::write_atomic(path, crate::history::trend::trend_html(&runs).as_bytes())?;
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
