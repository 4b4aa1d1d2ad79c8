//! One module per `probebridge` subcommand.

pub mod bench;
pub mod check;
pub mod demo;
pub mod estimator;
pub mod history;
pub mod opcua_certificate;
pub mod opcua_user;
pub mod probe;
pub mod run;
pub mod sim;

/// The most errors listed for one program; the rest are counted ("... and N more"),
/// so a 10 MB file of bad blocks does not flood the terminal.
pub const MAX_LISTED_ERRORS: usize = 100;

/// `program: error` per line on stderr, at most [`MAX_LISTED_ERRORS`] of them.
pub fn tell_errors<E: std::fmt::Display>(program: &std::path::Path, errors: &[E]) {
    for e in errors.iter().take(MAX_LISTED_ERRORS) {
        tell!("{}: {e}", program.display());
    }
    if errors.len() > MAX_LISTED_ERRORS {
        tell!(
            "{}: ... and {} more",
            program.display(),
            errors.len() - MAX_LISTED_ERRORS
        );
    }
}

/// Parses "X,Y,Z" into three numbers, naming the option on error.
pub fn parse_vec3(option: &str, s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("{option} {s:?}: expected three numbers X,Y,Z"));
    }
    let mut v = [0.0; 3];
    for (i, p) in parts.iter().enumerate() {
        v[i] = p
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{option} {s:?}: {p:?} is not a number"))?;
    }
    Ok(v)
}

/// The iceoryx2 service prefix of `--service` when none is given: the same for every
/// bridge and estimator on a gateway, so that they find each other.
pub fn default_service() -> String {
    "probebridge".to_string()
}
