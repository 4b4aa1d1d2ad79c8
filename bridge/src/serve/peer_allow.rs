//! The PLC face's peer allow-list (`plc.allow`): addresses and CIDR networks whose
//! connections are served; every other peer is refused at accept. Without the key any
//! peer is served.

use std::net::IpAddr;

/// One entry: a network (an address is a network of its full length).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Network {
    addr: IpAddr,
    prefix: u8,
}

impl Network {
    /// Parses `10.0.0.5`, `10.0.1.0/24`, `::1`, `fd00::/8`. Host bits set under the
    /// prefix (`10.0.1.7/24`) are a typing slip and refused.
    pub fn parse(s: &str) -> Result<Self, String> {
        let (addr, prefix) = match s.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (s, None),
        };
        let addr: IpAddr = addr
            .trim()
            .parse()
            .map_err(|_| format!("{s:?} is not an address or a network ADDRESS/BITS"))?;
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => match p.trim().parse::<u8>() {
                Ok(p) if p <= max => p,
                _ => return Err(format!("{s:?}: the prefix must be 0..{max}")),
            },
        };
        let net = Self { addr, prefix };
        if net.mask(addr) != bits(addr) {
            return Err(format!(
                "{s:?}: host bits are set below the /{prefix} prefix (did you mean {}/{prefix}?)",
                net.network_address()
            ));
        }
        Ok(net)
    }

    fn mask(&self, ip: IpAddr) -> u128 {
        let width = if ip.is_ipv4() { 32 } else { 128 };
        let host_bits = u32::from(width - self.prefix);
        let keep = if host_bits >= 128 {
            0
        } else {
            u128::MAX << host_bits
        };
        bits(ip) & keep
    }

    fn network_address(&self) -> IpAddr {
        let b = self.mask(self.addr);
        match self.addr {
            IpAddr::V4(_) => IpAddr::V4((b as u32).into()),
            IpAddr::V6(_) => IpAddr::V6(b.into()),
        }
    }

    pub fn contains(&self, ip: IpAddr) -> bool {
        // A peer of a dual-stack listener arrives as ::ffff:a.b.c.d.
        let ip = ip.to_canonical();
        ip.is_ipv4() == self.addr.is_ipv4() && self.mask(ip) == bits(self.addr)
    }
}

fn bits(ip: IpAddr) -> u128 {
    match ip {
        IpAddr::V4(a) => u128::from(u32::from(a)),
        IpAddr::V6(a) => u128::from(a),
    }
}

/// `None`: any peer; `Some`: only peers inside one of the networks.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AllowList(Option<Vec<Network>>);

impl AllowList {
    pub fn any() -> Self {
        Self(None)
    }

    /// The `plc.allow` entries; an error names the entry.
    pub fn parse(entries: &[String]) -> Result<Self, String> {
        if entries.is_empty() {
            return Err(
                "an empty list would refuse every peer; leave the key out to \
                 serve any peer"
                    .into(),
            );
        }
        entries
            .iter()
            .map(|e| Network::parse(e))
            .collect::<Result<Vec<_>, _>>()
            .map(|n| Self(Some(n)))
    }

    pub fn permits(&self, ip: IpAddr) -> bool {
        match &self.0 {
            None => true,
            Some(nets) => nets.iter().any(|n| n.contains(ip)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(e: &[&str]) -> AllowList {
        AllowList::parse(&e.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap()
    }

    #[test]
    fn addresses_and_networks_admit_their_peers_only() {
        let l = list(&["10.0.0.5", "10.0.1.0/24", "fd00::/8"]);
        for ok in [
            "10.0.0.5",
            "10.0.1.0",
            "10.0.1.255",
            "fd12::1",
            "::ffff:10.0.1.9",
        ] {
            assert!(l.permits(ok.parse().unwrap()), "{ok}");
        }
        for no in ["10.0.0.6", "10.0.2.1", "127.0.0.1", "fe80::1", "::1"] {
            assert!(!l.permits(no.parse().unwrap()), "{no}");
        }
        assert!(list(&["0.0.0.0/0"]).permits("192.168.3.4".parse().unwrap()));
        assert!(AllowList::any().permits("192.168.3.4".parse().unwrap()));
    }

    #[test]
    fn bad_entries_are_refused_with_the_entry() {
        for (bad, says) in [
            ("10.0.0", "not an address"),
            ("10.0.1.7/24", "10.0.1.0/24"),
            ("10.0.0.0/33", "0..32"),
            ("::1/129", "0..128"),
            ("plc.local", "not an address"),
        ] {
            let e = AllowList::parse(&[bad.to_string()]).unwrap_err();
            assert!(e.contains(bad) && e.contains(says), "{e}");
        }
        assert!(AllowList::parse(&[]).unwrap_err().contains("empty"));
    }
}
