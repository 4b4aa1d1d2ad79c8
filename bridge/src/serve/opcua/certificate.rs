//! The OPC UA face's application instance certificate (OPC 10000-4 §6.1): made by the
//! gateway in the PKI folder (async-opcua's layout) with the lifetime of
//! `opcua.certificate_days`, its subject alternative names the application URI, the
//! configured `hostname` and every address the endpoint listens on (for 0.0.0.0 the
//! host's addresses when it is made, or those of `opcua.certificate_addresses`).
//! Checked when `serve` starts and daily: an expired one stops `serve` until it is
//! renewed (`probebridge opcua-certificate --renew`), one that expires within
//! [`WARN_BEFORE_DAYS`] days is a warning.

use super::config::OpcuaSection;
use opcua::crypto::{CertificateStore, X509Data, X509};
use std::net::{IpAddr, SocketAddr};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

pub const WARN_BEFORE_DAYS: i64 = 30;
/// How often a running face looks at its certificate again.
pub const CHECK_EVERY: Duration = Duration::from_secs(24 * 3600);
const KEY_BITS: u32 = 2048;
const DAY_S: i64 = 24 * 3600;

/// What the face's certificate is made of.
pub struct Identity {
    pub application_uri: String,
    pub application_name: String,
    /// DNS names and IP addresses, the configured host name first.
    pub names: Vec<String>,
    pub days: u32,
}

impl Identity {
    pub fn new(section: &OpcuaSection, bind: SocketAddr, host: &str, machine: &str) -> Self {
        let mut names = vec![host.trim_matches(['[', ']']).to_string()];
        let listened: Vec<IpAddr> = if !section.certificate_addresses.is_empty() {
            section.certificate_addresses.clone()
        } else if bind.ip().is_unspecified() {
            host_addresses(bind.is_ipv6())
        } else {
            vec![bind.ip()]
        };
        for a in listened {
            let a = a.to_string();
            if !names.contains(&a) {
                names.push(a);
            }
        }
        Self {
            application_uri: application_uri(host, machine),
            application_name: format!("probebridge {machine}"),
            names,
            days: section.certificate_days,
        }
    }

    fn x509(&self) -> X509Data {
        // Only these names: not the stack's guesses (localhost, the host's name).
        let alt = X509Data::alt_host_names(
            &self.application_uri,
            Some(self.names.clone()),
            false,
            false,
            false,
        );
        X509Data {
            key_size: KEY_BITS,
            common_name: self.application_name.clone(),
            organization: "probebridge".into(),
            organizational_unit: "OPC UA face".into(),
            country: "DE".into(),
            state: String::new(),
            alt_host_names: alt,
            certificate_duration_days: self.days,
        }
    }
}

/// The server's application URI (the certificate's first name).
pub fn application_uri(host: &str, machine: &str) -> String {
    format!("urn:probebridge:{host}:{machine}")
}

/// The host's own addresses (every interface's, loopback included) of the family.
fn host_addresses(v6: bool) -> Vec<IpAddr> {
    let mut out = Vec::new();
    let mut list: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs fills `list`, freed below with freeifaddrs; each entry's
    // address is read as the sockaddr its family says.
    unsafe {
        if libc::getifaddrs(&mut list) != 0 {
            return out;
        }
        let mut p = list;
        while !p.is_null() {
            let a = (*p).ifa_addr;
            if !a.is_null() {
                match i32::from((*a).sa_family) {
                    libc::AF_INET => {
                        let s = &*(a as *const libc::sockaddr_in);
                        out.push(IpAddr::from(u32::from_be(s.sin_addr.s_addr).to_be_bytes()));
                    }
                    libc::AF_INET6 if v6 => {
                        let s = &*(a as *const libc::sockaddr_in6);
                        out.push(IpAddr::from(s.sin6_addr.s6_addr));
                    }
                    _ => {}
                }
            }
            p = (*p).ifa_next;
        }
        libc::freeifaddrs(list);
    }
    out.sort();
    out.dedup();
    out
}

/// The certificate's files.
pub struct Files {
    pub cert: PathBuf,
    pub key: PathBuf,
}

impl Files {
    pub fn new(pki: &Path, cert: &str, key: &str) -> Self {
        Self {
            cert: pki.join(cert),
            key: pki.join(key),
        }
    }
}

/// How long a certificate is still valid (negative: expired that long ago), and when.
pub struct Validity {
    pub left_s: i64,
    pub not_after: String,
}

impl Validity {
    pub fn of(cert: &X509, now: SystemTime) -> Result<Self, String> {
        let end = cert
            .not_after()
            .map_err(|_| "its validity cannot be read".to_string())?;
        let now = now
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64);
        Ok(Self {
            left_s: end.timestamp() - now,
            not_after: end.to_rfc3339(),
        })
    }

    /// The log's warning, when it expires within [`WARN_BEFORE_DAYS`] days.
    pub fn warning(&self, file: &Path) -> Option<String> {
        (self.left_s <= WARN_BEFORE_DAYS * DAY_S).then(|| {
            format!(
                "OPC UA face: the server certificate {} expires in {} days ({}): renew it \
                 with `probebridge opcua-certificate --renew` and let the clients trust the \
                 new one",
                file.display(),
                self.left_s.max(0) / DAY_S,
                self.not_after
            )
        })
    }
}

/// Reads the certificate (`None`: there is none yet).
pub fn read(files: &Files) -> Result<Option<X509>, String> {
    if !files.cert.exists() {
        return Ok(None);
    }
    CertificateStore::read_cert(&files.cert)
        .map(Some)
        .map_err(|e| format!("{}: {e}", files.cert.display()))
}

/// Makes a new certificate and key (replacing any; the key readable by the service's
/// user only); its validity.
pub fn make(files: &Files, who: &Identity) -> Result<Validity, String> {
    let (cert, _) =
        CertificateStore::create_certificate_and_key(&who.x509(), true, &files.cert, &files.key)
            .map_err(|e| format!("cannot make the certificate {}: {e}", files.cert.display()))?;
    std::fs::set_permissions(&files.key, std::fs::Permissions::from_mode(0o600))
        .map_err(|e| format!("{}: {e}", files.key.display()))?;
    Validity::of(&cert, SystemTime::now())
}

/// At start: makes the certificate if there is none; an expired one is an error
/// (nothing is replaced without being asked); one close to expiry a warning.
pub fn check_at_start(files: &Files, who: &Identity) -> Result<(), String> {
    let Some(cert) = read(files)? else {
        let v = make(files, who)?;
        tracing::info!(
            certificate = %files.cert.display(),
            names = ?who.names,
            not_after = %v.not_after,
            "OPC UA face: made the server certificate"
        );
        if let Some(w) = v.warning(&files.cert) {
            tracing::warn!("{w}");
        }
        return Ok(());
    };
    let v = Validity::of(&cert, SystemTime::now())
        .map_err(|e| format!("{}: {e}", files.cert.display()))?;
    if v.left_s <= 0 {
        return Err(format!(
            "the server certificate {} expired on {}: renew it with `probebridge \
             opcua-certificate --renew` (clients must then trust the new one, see \
             docs/opcua.md)",
            files.cert.display(),
            v.not_after
        ));
    }
    if let Some(w) = v.warning(&files.cert) {
        tracing::warn!("{w}");
    }
    Ok(())
}

/// The daily check of a running face: the warning, if due.
pub fn check_now(files: &Files) -> Option<String> {
    match read(files).and_then(|c| {
        c.ok_or_else(|| "it is gone".to_string())
            .and_then(|c| Validity::of(&c, SystemTime::now()))
    }) {
        Ok(v) => v.warning(&files.cert),
        Err(e) => Some(format!(
            "OPC UA face: the server certificate {}: {e}",
            files.cert.display()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_names_hold_the_host_name_and_every_listened_address() {
        let s: OpcuaSection = toml::from_str("").unwrap();
        let who = Identity::new(&s, "192.0.2.7:4840".parse().unwrap(), "gw-7", "m");
        assert_eq!(who.names, ["gw-7", "192.0.2.7"]);
        assert_eq!(who.application_uri, "urn:probebridge:gw-7:m");
        // 0.0.0.0: the host's addresses (loopback at least), or the configured ones.
        let any = Identity::new(&s, "0.0.0.0:4840".parse().unwrap(), "gw-7", "m");
        assert!(
            any.names.contains(&"127.0.0.1".to_string()),
            "{:?}",
            any.names
        );
        let s: OpcuaSection =
            toml::from_str("certificate_addresses = [\"10.0.0.5\", \"fd00::5\"]").unwrap();
        let named = Identity::new(&s, "0.0.0.0:4840".parse().unwrap(), "gw-7", "m");
        assert_eq!(named.names, ["gw-7", "10.0.0.5", "fd00::5"]);
    }
}
