//! Who may write the request block: the connection that wrote first, for as long as
//! it keeps talking. An owner silent for `plc.owner_timeout_ms` loses the block to the
//! next writer, and a newer connection from the owner's own address takes it over as
//! soon as the owner has been silent for [`SAME_ADDRESS_SILENCE`] (a PLC that
//! rebooted while its old connection is still half-open: a reboot takes longer than
//! that, while a PLC that owns the block talks every cycle, so a second client on the
//! PLC's host or behind its NAT cannot snatch a live PLC's block).

use std::net::IpAddr;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Owner {
    conn: u64,
    ip: IpAddr,
    heard: Instant,
}

/// How long an owner must have been silent before a newer connection from its
/// address takes the block over (or the owner timeout, if shorter).
pub const SAME_ADDRESS_SILENCE: Duration = Duration::from_secs(3);

/// The block is another connection's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Busy;

/// Why the block changed hands (logged).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Takeover {
    /// The owner said nothing for this long.
    Silent { from: u64, silent: Duration },
    /// A newer connection from the owner's address.
    SameAddress { from: u64 },
}

#[derive(Clone, Debug)]
pub struct Ownership {
    owner: Option<Owner>,
    timeout: Duration,
}

impl Ownership {
    pub fn new(timeout: Duration) -> Self {
        Self {
            owner: None,
            timeout,
        }
    }

    /// Connection `conn` (ids grow with every connection) from `ip` wants to write.
    /// `Ok(Some)`: it took the block over from another.
    pub fn claim(&mut self, conn: u64, ip: IpAddr, now: Instant) -> Result<Option<Takeover>, Busy> {
        let takeover = match self.owner {
            None => None,
            Some(o) if o.conn == conn => None,
            Some(o) => {
                let silent = now.saturating_duration_since(o.heard);
                if o.ip == ip && conn > o.conn && silent >= SAME_ADDRESS_SILENCE.min(self.timeout) {
                    Some(Takeover::SameAddress { from: o.conn })
                } else if silent >= self.timeout {
                    Some(Takeover::Silent {
                        from: o.conn,
                        silent,
                    })
                } else {
                    return Err(Busy);
                }
            }
        };
        self.owner = Some(Owner {
            conn,
            ip,
            heard: now,
        });
        Ok(takeover)
    }

    /// Any request of connection `conn` (a read too) keeps its ownership alive.
    pub fn heard(&mut self, conn: u64, now: Instant) {
        if let Some(o) = self.owner.as_mut().filter(|o| o.conn == conn) {
            o.heard = now;
        }
    }

    pub fn disconnected(&mut self, conn: u64) {
        if self.owner.is_some_and(|o| o.conn == conn) {
            self.owner = None;
        }
    }

    pub fn owner(&self) -> Option<u64> {
        self.owner.map(|o| o.conn)
    }

    /// The owner's address, while there is one.
    pub fn owner_ip(&self) -> Option<IpAddr> {
        self.owner.map(|o| o.ip)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLC: &str = "10.0.0.5";
    const OTHER: &str = "10.0.0.9";

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn the_first_writer_owns_while_it_talks() {
        let t0 = Instant::now();
        let mut o = Ownership::new(Duration::from_secs(10));
        assert_eq!(o.claim(1, ip(PLC), t0), Ok(None));
        assert_eq!(
            o.claim(2, ip(OTHER), t0 + Duration::from_secs(9)),
            Err(Busy)
        );
        // A read at 9 s keeps it: still the owner's at 18 s.
        o.heard(1, t0 + Duration::from_secs(9));
        o.heard(2, t0 + Duration::from_secs(18));
        assert_eq!(
            o.claim(2, ip(OTHER), t0 + Duration::from_secs(18)),
            Err(Busy)
        );
        assert_eq!(o.owner(), Some(1));
        o.disconnected(2);
        assert_eq!(o.owner(), Some(1));
        o.disconnected(1);
        assert_eq!(
            o.claim(2, ip(OTHER), t0 + Duration::from_secs(18)),
            Ok(None)
        );
    }

    #[test]
    fn a_silent_owner_loses_the_block() {
        let t0 = Instant::now();
        let mut o = Ownership::new(Duration::from_secs(10));
        o.claim(1, ip(OTHER), t0).unwrap();
        let later = t0 + Duration::from_secs(10);
        assert_eq!(
            o.claim(2, ip(PLC), later),
            Ok(Some(Takeover::Silent {
                from: 1,
                silent: Duration::from_secs(10)
            }))
        );
        assert_eq!(o.claim(1, ip(OTHER), later), Err(Busy));
    }

    #[test]
    fn a_newer_connection_from_the_owners_address_takes_over_a_silent_owner() {
        let t0 = Instant::now();
        let mut o = Ownership::new(Duration::from_secs(10));
        o.claim(4, ip(PLC), t0).unwrap();
        // A live owner (heard within 3 s) keeps it, even against its address.
        o.heard(4, t0 + Duration::from_millis(500));
        assert_eq!(
            o.claim(7, ip(PLC), t0 + Duration::from_millis(3400)),
            Err(Busy)
        );
        let t = t0 + Duration::from_millis(3500);
        assert_eq!(
            o.claim(7, ip(PLC), t),
            Ok(Some(Takeover::SameAddress { from: 4 }))
        );
        // The old (half-open) one does not take it back.
        assert_eq!(o.claim(4, ip(PLC), t), Err(Busy));
        assert_eq!(o.owner(), Some(7));
    }
}
