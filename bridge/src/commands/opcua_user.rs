//! `probebridge opcua-user NAME`: the users file's line for NAME (see
//! `serve::opcua::users`), the password read from the first line of standard input,
//! so it never shows in the process list or the shell's history.

use std::io::BufRead;

pub fn run(name: &str) -> Result<(), String> {
    let mut password = String::new();
    std::io::stdin()
        .lock()
        .read_line(&mut password)
        .map_err(|e| format!("cannot read the password from standard input: {e}"))?;
    let password = password.strip_suffix('\n').unwrap_or(&password);
    let password = password.strip_suffix('\r').unwrap_or(password);
    let line = crate::serve::opcua::users::line(name, password)?;
    crate::say!("{line}");
    Ok(())
}
