//! The OPC UA face's users file: one `NAME:HASH` a line, HASH an argon2id password
//! hash in the PHC string format (`probebridge opcua-user NAME` makes the line; `#`
//! begins a comment). The file holds no password, and still must be readable by the
//! service's user only: a file others may read or write is refused at start.

use argon2::password_hash::rand_core::OsRng;
use argon2::password_hash::{PasswordHash, PasswordHasher, PasswordVerifier, SaltString};
use argon2::Argon2;
use std::collections::BTreeMap;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;

/// The users, by name, with their hashes.
#[derive(Clone, Debug, Default)]
pub struct Users {
    hashes: BTreeMap<String, String>,
}

/// The longest users file read (it is a short list).
const MAX_FILE_BYTES: u64 = 1 << 20;

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '@'))
}

impl Users {
    /// Reads `path`; a missing file is no users (anonymous reading only). `Err` says
    /// the file, the line and why.
    pub fn load(path: &Path) -> Result<Self, String> {
        let meta = match std::fs::metadata(path) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Self::default()),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(format!(
                "{}: other users may read or write it (mode {mode:o}): `chmod 600` it, owned \
                 by the service's user",
                path.display()
            ));
        }
        if meta.len() > MAX_FILE_BYTES {
            return Err(format!(
                "{}: larger than {MAX_FILE_BYTES} bytes",
                path.display()
            ));
        }
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn parse(text: &str) -> Result<Self, String> {
        let mut hashes = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let n = i + 1;
            let Some((name, hash)) = line.split_once(':') else {
                return Err(format!("line {n}: expected NAME:HASH"));
            };
            if !valid_name(name) {
                return Err(format!(
                    "line {n}: user name {name:?}: 1..64 of letters, digits, _ - . @"
                ));
            }
            let parsed = PasswordHash::new(hash)
                .map_err(|e| format!("line {n}: user {name}: not a PHC hash string ({e})"))?;
            if parsed.algorithm.as_str() != "argon2id" {
                return Err(format!(
                    "line {n}: user {name}: {} hash; expected argon2id (make the line with \
                     `probebridge opcua-user {name}`)",
                    parsed.algorithm
                ));
            }
            if hashes.insert(name.to_string(), hash.to_string()).is_some() {
                return Err(format!("line {n}: user {name} is given twice"));
            }
        }
        Ok(Self { hashes })
    }

    pub fn is_empty(&self) -> bool {
        self.hashes.is_empty()
    }

    pub fn len(&self) -> usize {
        self.hashes.len()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.hashes.contains_key(name)
    }

    /// Whether `password` is `name`'s. Slow on purpose (argon2id): call it off the
    /// runtime's threads.
    pub fn verify(&self, name: &str, password: &str) -> bool {
        let Some(hash) = self.hashes.get(name) else {
            return false;
        };
        PasswordHash::new(hash).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        })
    }
}

/// The users file's line for `name` with `password` (argon2id, a fresh random salt,
/// the crate's default cost: 19 MiB, 2 passes).
pub fn line(name: &str, password: &str) -> Result<String, String> {
    if !valid_name(name) {
        return Err(format!(
            "user name {name:?}: 1..64 of letters, digits, _ - . @"
        ));
    }
    if password.is_empty() {
        return Err("the password is empty".into());
    }
    let salt = SaltString::generate(&mut OsRng);
    let hash = Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .map_err(|e| format!("cannot hash the password: {e}"))?;
    Ok(format!("{name}:{hash}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_verifies_its_password_only() {
        let l = line("mes", "secret 1").unwrap();
        assert!(l.starts_with("mes:$argon2id$"), "{l}");
        assert!(!l.contains("secret"), "{l}");
        let users = Users::parse(&format!("# the MES\n\n{l}\n")).unwrap();
        assert_eq!(users.len(), 1);
        assert!(users.verify("mes", "secret 1"));
        assert!(!users.verify("mes", "secret 2"));
        assert!(!users.verify("other", "secret 1"));
    }

    #[test]
    fn bad_lines_say_where_and_why() {
        for (text, part) in [
            ("mes", "line 1: expected NAME:HASH"),
            ("\nm e:$argon2id$x", "line 2: user name"),
            ("mes:plain", "not a PHC"),
            (
                "mes:$pbkdf2-sha256$i=1000$c2FsdHNhbHQ$aGFzaGhhc2hoYXNoaGFzaA",
                "expected argon2id",
            ),
        ] {
            let e = Users::parse(text).unwrap_err();
            assert!(e.contains(part), "{text}: {e}");
        }
        let l = line("a", "p").unwrap();
        let e = Users::parse(&format!("{l}\n{l}")).unwrap_err();
        assert!(e.contains("line 2: user a is given twice"), "{e}");
        assert!(line("", "p").is_err());
        assert!(line("a", "").is_err());
    }

    #[test]
    fn a_file_others_may_read_is_refused_and_a_missing_one_is_empty() {
        let dir = std::env::temp_dir().join(format!("pb-opcua-users-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("users");
        std::fs::write(&f, line("mes", "pw").unwrap()).unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = Users::load(&f).unwrap_err();
        assert!(e.contains("mode 644") && e.contains("chmod 600"), "{e}");
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(Users::load(&f).unwrap().len(), 1);
        assert!(Users::load(&dir.join("none")).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
