//! Machine endpoints (`machines:` in a graph): what dynaflow accepts as a zenoh endpoint, and
//! one spelling per socket so two machines that name the same socket two ways are caught.

/// A zenoh endpoint: `tcp/HOST:PORT`, or `tls/HOST:PORT` for mutually authenticated TLS (the
/// transports dynaflow builds zenoh with).
pub(crate) fn check_endpoint(endpoint: &str) -> Result<(), String> {
    canonical_endpoint(endpoint).map(|_| ())
}

/// The host and port an endpoint listens on, in one spelling per socket: an IP address in its
/// standard form (`[0:0:0:0:0:0:0:1]` is `::1`), `localhost` as `127.0.0.1`, the port as a
/// number (`07447` is `7447`); so two machines that name one socket two ways are caught. A
/// host name is kept as written, lower-cased (DNS names are case-insensitive).
pub(crate) fn canonical_endpoint(endpoint: &str) -> Result<(String, u16), String> {
    let Some(addr) = endpoint.strip_prefix("tcp/").or_else(|| endpoint.strip_prefix("tls/")) else {
        return Err("not a `tcp/` or `tls/` endpoint (dynaflow builds zenoh with these transports only)".into());
    };
    let (host, port) = if let Some(rest) = addr.strip_prefix('[') {
        let Some((ip, port)) = rest.split_once("]:") else {
            return Err("an IPv6 host is written `[ADDRESS]:PORT`".into());
        };
        let ip: std::net::Ipv6Addr = ip.parse().map_err(|_| format!("`{ip}` is not an IPv6 address"))?;
        (ip.to_string(), port)
    } else {
        let Some((host, port)) = addr.split_once(':') else {
            return Err("no `:PORT`".into());
        };
        if host.is_empty() {
            return Err("no host".into());
        }
        if let Ok(ip) = host.parse::<std::net::Ipv4Addr>() {
            (ip.to_string(), port)
        } else {
            // RFC 1123 host names: labels of letters, digits and `-`, joined by dots.
            let label_ok =
                |l: &str| !l.is_empty() && l.len() <= 63 && l.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-');
            if host.len() > 253 || !host.split('.').all(label_ok) {
                return Err(format!("`{host}` is not a host name or IP address (IPv6 goes in brackets: `[::1]:7447`)"));
            }
            let host = host.to_ascii_lowercase();
            (if host == "localhost" { "127.0.0.1".to_owned() } else { host }, port)
        }
    };
    if port.is_empty() || !port.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!("port `{port}` is not a number"));
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => Ok((host, p)),
        _ => Err(format!("port `{port}` is not in 1..=65535")),
    }
}
