//! The source a connection is counted against by the per-address limits: its IPv4 address, or the /64
//! prefix of its IPv6 address (one machine or one home network usually holds a whole /64, so counting
//! single IPv6 addresses would give each attacker 2^64 budgets). An IPv4 address mapped into IPv6
//! (`::ffff:a.b.c.d`, what a dual-stack socket reports) counts as the IPv4 address.

use std::fmt;
use std::net::{IpAddr, Ipv4Addr};

/// What the per-address limits count by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) enum Source {
    /// An IPv4 address.
    V4(Ipv4Addr),
    /// The first 64 bits of an IPv6 address.
    V6Prefix(u64),
}

impl Source {
    /// The source of a peer at `ip`.
    pub(crate) fn of(ip: IpAddr) -> Source {
        match ip {
            IpAddr::V4(v4) => Source::V4(v4),
            IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
                Some(v4) => Source::V4(v4),
                None => Source::V6Prefix((v6.to_bits() >> 64) as u64),
            },
        }
    }
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Source::V4(ip) => write!(f, "{ip}"),
            Source::V6Prefix(p) => {
                let ip = std::net::Ipv6Addr::from_bits(u128::from(*p) << 64);
                write!(f, "{ip}/64")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn src(s: &str) -> Source {
        Source::of(s.parse().unwrap())
    }

    #[test]
    fn ipv4_counts_by_address_and_ipv6_by_its_64_prefix() {
        assert_eq!(src("10.0.0.1"), src("::ffff:10.0.0.1"));
        assert_ne!(src("10.0.0.1"), src("10.0.0.2"));
        assert_eq!(src("2001:db8::1"), src("2001:db8::ffff:1"));
        assert_ne!(src("2001:db8::1"), src("2001:db8:0:1::1"));
        assert_eq!(src("2001:db8::1").to_string(), "2001:db8::/64");
        assert_eq!(src("127.0.0.1").to_string(), "127.0.0.1");
    }
}
