//! Where a webhook may go: no server-side request forgery.
//!
//! A `webhook_url` is the client's choice of where the server sends a request, so it must not
//! reach what only the server can: its own loopback, the cloud metadata address (169.254.169.254),
//! the private network behind it. The URL must be http(s); its host is resolved and every address
//! it resolves to must be global, unless the operator lists the URL's `host:port` in
//! `webhook_allowed_hosts`. The check runs at submission (a 422 names why) and again before each
//! delivery (DNS may have changed since), and the delivery connects to the very addresses
//! checked, never following a redirect.
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::time::Duration;
use url::Url;

/// Longest a webhook host's DNS lookup may take.
const RESOLVE_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest accepted `webhook_url`.
pub const MAX_URL_LEN: usize = 2048;

/// Why a webhook URL is refused.
#[derive(Debug, thiserror::Error)]
pub enum Refused {
    #[error("it is not a URL ({0})")]
    NotAUrl(String),
    #[error("it is longer than {MAX_URL_LEN} characters")]
    TooLong,
    #[error("its scheme is {0}; only http and https are sent to")]
    Scheme(String),
    #[error("it has no host")]
    NoHost,
    #[error("it carries a user name or password; put credentials in the path or query instead")]
    Credentials,
    #[error("its host {host} does not resolve ({reason})")]
    Resolve { host: String, reason: String },
    #[error("its host {host} resolves to {addr}, a {kind} address; the server's operator may allow {host_port} in webhook_allowed_hosts")]
    NotGlobal {
        host: String,
        host_port: String,
        addr: IpAddr,
        kind: &'static str,
    },
}

impl Refused {
    /// Stable kebab-case name of the reason.
    pub fn code(&self) -> &'static str {
        match self {
            Refused::NotAUrl(_) => "not-a-url",
            Refused::TooLong => "too-long",
            Refused::Scheme(_) => "scheme",
            Refused::NoHost => "no-host",
            Refused::Credentials => "credentials",
            Refused::Resolve { .. } => "unresolved",
            Refused::NotGlobal { .. } => "not-global",
        }
    }
}

/// A checked URL and the addresses a delivery may connect to.
#[derive(Debug, Clone)]
pub struct Target {
    pub url: Url,
    /// The host as the URL names it (a domain, or an address literal).
    pub host: String,
    pub addrs: Vec<SocketAddr>,
}

/// Checks `raw` and resolves its host. `allowed` holds lowercase `host:port` pairs.
pub async fn check(raw: &str, allowed: &[String]) -> Result<Target, Refused> {
    if raw.len() > MAX_URL_LEN {
        return Err(Refused::TooLong);
    }
    let url = Url::parse(raw).map_err(|e| Refused::NotAUrl(e.to_string()))?;
    if !matches!(url.scheme(), "http" | "https") {
        return Err(Refused::Scheme(url.scheme().to_string()));
    }
    if !url.username().is_empty() || url.password().is_some() {
        return Err(Refused::Credentials);
    }
    let host = url.host().ok_or(Refused::NoHost)?;
    let port = url.port_or_known_default().ok_or(Refused::NoHost)?;
    // `host_str` keeps an IPv6 literal's brackets, as `host:port` writes it.
    let host_text = url.host_str().ok_or(Refused::NoHost)?.to_ascii_lowercase();
    let host_port = format!("{host_text}:{port}");
    let addrs: Vec<SocketAddr> = match host {
        url::Host::Ipv4(ip) => vec![SocketAddr::new(IpAddr::V4(ip), port)],
        url::Host::Ipv6(ip) => vec![SocketAddr::new(IpAddr::V6(ip), port)],
        url::Host::Domain(domain) => {
            let lookup = tokio::net::lookup_host((domain, port));
            match tokio::time::timeout(RESOLVE_TIMEOUT, lookup).await {
                Ok(Ok(found)) => found.collect(),
                Ok(Err(e)) => {
                    return Err(Refused::Resolve {
                        host: host_text,
                        reason: e.to_string(),
                    })
                }
                Err(_) => {
                    return Err(Refused::Resolve {
                        host: host_text,
                        reason: format!("no answer within {} s", RESOLVE_TIMEOUT.as_secs()),
                    })
                }
            }
        }
    };
    if addrs.is_empty() {
        return Err(Refused::Resolve {
            host: host_text,
            reason: "no address".into(),
        });
    }
    if !allowed.contains(&host_port) {
        // Every address, not the first: the client connects to any of them.
        for addr in &addrs {
            if let Some(kind) = not_global(addr.ip()) {
                return Err(Refused::NotGlobal {
                    host: host_text,
                    host_port,
                    addr: addr.ip(),
                    kind,
                });
            }
        }
    }
    Ok(Target {
        url,
        host: host_text,
        addrs,
    })
}

/// What kind of non-global address `ip` is, or `None` for a global one. Follows the IANA
/// special-purpose registries; IPv6 is global only inside 2000::/3 (global unicast), less its
/// special blocks, and an IPv4-mapped or -translated address is judged as the IPv4 it carries.
pub fn not_global(ip: IpAddr) -> Option<&'static str> {
    match ip {
        IpAddr::V4(v4) => not_global_v4(v4),
        IpAddr::V6(v6) => not_global_v6(v6),
    }
}

fn not_global_v4(ip: Ipv4Addr) -> Option<&'static str> {
    let [a, b, c, _] = ip.octets();
    Some(if ip.is_unspecified() || a == 0 {
        "unspecified (\"this network\")"
    } else if ip.is_loopback() {
        "loopback"
    } else if ip.is_private() {
        "private"
    } else if ip.is_link_local() {
        "link-local"
    } else if a == 100 && (64..128).contains(&b) {
        "shared (carrier-grade NAT)"
    } else if ip.is_multicast() {
        "multicast"
    } else if ip.is_broadcast() {
        "broadcast"
    } else if ip.is_documentation() {
        "documentation"
    } else if a == 192 && b == 0 && c == 0 {
        "IETF protocol assignment"
    } else if a == 198 && (18..20).contains(&b) {
        "benchmarking"
    } else if a >= 240 {
        "reserved"
    } else {
        return None;
    })
}

fn not_global_v6(ip: Ipv6Addr) -> Option<&'static str> {
    if let Some(v4) = ip.to_ipv4_mapped() {
        return not_global_v4(v4);
    }
    let s = ip.segments();
    // NAT64 (64:ff9b::/96) reaches the IPv4 address it carries.
    if s[0] == 0x64 && s[1] == 0xff9b && s[2..6] == [0, 0, 0, 0] {
        let [a, b] = s[6].to_be_bytes();
        let [c, d] = s[7].to_be_bytes();
        return not_global_v4(Ipv4Addr::new(a, b, c, d));
    }
    Some(if ip.is_unspecified() {
        "unspecified"
    } else if ip.is_loopback() {
        "loopback"
    } else if ip.is_multicast() {
        "multicast"
    } else if s[0] & 0xfe00 == 0xfc00 {
        "unique-local"
    } else if s[0] & 0xffc0 == 0xfe80 {
        "link-local"
    } else if s[0] & 0xffc0 == 0xfec0 {
        "site-local"
    } else if s[0] == 0x2001 && s[1] == 0x0db8 {
        "documentation"
    } else if s[0] == 0x2001 && s[1] < 0x0200 {
        "IETF protocol assignment (Teredo, benchmarking, ORCHID)"
    } else if s[0] == 0x2002 {
        "6to4"
    } else if s[0] & 0xe000 != 0x2000 {
        "reserved (outside global unicast 2000::/3)"
    } else {
        return None;
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kind(ip: &str) -> Option<&'static str> {
        not_global(ip.parse().expect("ip"))
    }

    #[test]
    fn global_addresses_pass_and_every_special_block_is_named() {
        for ip in [
            "93.184.215.14",
            "8.8.8.8",
            "2606:4700::1111",
            "2a00:1450:4001::200e",
        ] {
            assert_eq!(kind(ip), None, "{ip}");
        }
        for (ip, expected) in [
            ("127.0.0.1", "loopback"),
            ("10.1.2.3", "private"),
            ("172.16.0.1", "private"),
            ("192.168.1.1", "private"),
            ("169.254.169.254", "link-local"),
            ("0.0.0.0", "unspecified (\"this network\")"),
            ("100.64.0.1", "shared (carrier-grade NAT)"),
            ("224.0.0.1", "multicast"),
            ("255.255.255.255", "broadcast"),
            ("::1", "loopback"),
            ("::", "unspecified"),
            ("fd00::1", "unique-local"),
            ("fe80::1", "link-local"),
            ("ff02::1", "multicast"),
            ("::ffff:127.0.0.1", "loopback"),
            ("::ffff:169.254.169.254", "link-local"),
            ("64:ff9b::a00:1", "private"),
            ("2001:db8::1", "documentation"),
        ] {
            assert_eq!(kind(ip), Some(expected), "{ip}");
        }
    }

    #[tokio::test]
    async fn urls_are_refused_by_scheme_host_and_address_unless_allowed() {
        let refused = |r: Result<Target, Refused>| r.err().map(|e| e.code());
        assert_eq!(
            refused(check("ftp://example.com/x", &[]).await),
            Some("scheme")
        );
        assert_eq!(refused(check("not a url", &[]).await), Some("not-a-url"));
        assert_eq!(
            refused(check("http://u:p@8.8.8.8/", &[]).await),
            Some("credentials")
        );
        assert_eq!(
            refused(check("http://127.0.0.1:9000/hook", &[]).await),
            Some("not-global")
        );
        assert_eq!(
            refused(check("http://[::1]:9000/hook", &[]).await),
            Some("not-global")
        );
        assert_eq!(
            refused(check("http://localhost:9000/hook", &[]).await),
            Some("not-global")
        );
        // 2130706433 is 127.0.0.1 written as one number; the URL parser reads it as an address.
        assert_eq!(
            refused(check("http://2130706433:9000/", &[]).await),
            Some("not-global")
        );
        let allowed = vec!["127.0.0.1:9000".to_string(), "[::1]:9000".to_string()];
        let target = check("http://127.0.0.1:9000/hook", &allowed)
            .await
            .expect("allowed");
        assert_eq!(target.addrs, vec!["127.0.0.1:9000".parse().expect("addr")]);
        check("http://[::1]:9000/hook", &allowed)
            .await
            .expect("allowed v6");
        // The allowance is for that port only.
        assert_eq!(
            refused(check("http://127.0.0.1:9001/", &allowed).await),
            Some("not-global")
        );
    }
}
