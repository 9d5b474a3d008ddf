//! What the daemon refuses before any handler runs: requests a browser could forge.
//!
//! A web page open on the lab PC can send requests to a loopback service, and a DNS-rebinding
//! page can even read the answers. So, for every request:
//! - `Host` must name this daemon: the address it listens on (`localhost` too on loopback), any
//!   IP literal when it listens on all interfaces (rebinding needs a domain name), or a name in
//!   `daemon.allowed_hosts`; always with the listening port.
//! - When a token is set, every route needs it: `Authorization: Bearer <token>` (scheme in any
//!   case) or the HttpOnly cookie `/api/login` sets. Compared in constant time.
//! - A state-changing request (anything but GET/HEAD) needs `Content-Type: application/json`
//!   (which a page can only send cross-origin after a CORS preflight, and the daemon answers
//!   none) and either no `Origin` or this daemon's own.

use axum::http::{header, HeaderMap, Method};
use std::net::{IpAddr, SocketAddr};

/// The cookie that carries the token for the page, set by `POST /api/login`.
pub const TOKEN_COOKIE: &str = "impactcam_token";

/// What a request must satisfy; built once when the daemon binds.
pub struct RequestGuard {
    bound: SocketAddr,
    allowed_names: Vec<String>,
    token: Option<String>,
}

/// Why a request was refused: (HTTP status, message).
#[derive(Debug, PartialEq)]
pub struct Refusal(pub u16, pub String);

impl RequestGuard {
    pub fn new(bound: SocketAddr, allowed_hosts: &[String], token: Option<String>) -> Self {
        RequestGuard {
            bound,
            allowed_names: allowed_hosts
                .iter()
                .map(|h| h.to_ascii_lowercase())
                .collect(),
            token,
        }
    }

    pub fn token_required(&self) -> bool {
        self.token.is_some()
    }

    /// Whether `Host` names this daemon.
    pub fn host_allowed(&self, host: &str) -> bool {
        let host = host.trim().to_ascii_lowercase();
        let (name, port) = match split_host_port(&host) {
            Some(x) => x,
            None => return false,
        };
        if port != Some(self.bound.port()) {
            return false;
        }
        if self.allowed_names.iter().any(|n| n == name) {
            return true;
        }
        let ip = self.bound.ip();
        if ip.is_loopback() && name == "localhost" {
            return true;
        }
        match name
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<IpAddr>()
        {
            Ok(given) => {
                given == ip || ip.is_unspecified() || (ip.is_loopback() && given.is_loopback())
            }
            Err(_) => false,
        }
    }

    /// Whether the request carries the token (always true when none is set).
    pub fn authorised(&self, headers: &HeaderMap) -> bool {
        let Some(token) = &self.token else {
            return true;
        };
        let bearer = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| {
                let (scheme, rest) = v.trim().split_once(' ')?;
                scheme.eq_ignore_ascii_case("bearer").then(|| rest.trim())
            });
        if bearer.is_some_and(|given| constant_time_eq(given.as_bytes(), token.as_bytes())) {
            return true;
        }
        cookie(headers, TOKEN_COOKIE)
            .is_some_and(|given| constant_time_eq(given.as_bytes(), token.as_bytes()))
    }

    /// Whether `given` is the token (for the login route).
    pub fn token_matches(&self, given: &str) -> bool {
        self.token
            .as_ref()
            .is_some_and(|t| constant_time_eq(given.as_bytes(), t.as_bytes()))
    }

    /// The checks that do not depend on the route: Host, then for state-changing methods
    /// Content-Type and Origin. (The token is checked by the caller, which knows which routes
    /// answer a login page instead.)
    pub fn check(&self, method: &Method, headers: &HeaderMap) -> Result<(), Refusal> {
        let host = headers
            .get(header::HOST)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        if !self.host_allowed(host) {
            return Err(Refusal(
                421,
                format!("Host {host:?} is not this daemon's address ({}); add the name to daemon.allowed_hosts to use it", self.bound),
            ));
        }
        if method == Method::GET || method == Method::HEAD {
            return Ok(());
        }
        let json = headers
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .map(|v| v.split(';').next().unwrap_or("").trim())
            .is_some_and(|essence| essence.eq_ignore_ascii_case("application/json"));
        if !json {
            return Err(Refusal(
                415,
                "this request changes state: send Content-Type: application/json".into(),
            ));
        }
        if let Some(origin) = headers.get(header::ORIGIN) {
            let origin = origin.to_str().unwrap_or("").to_ascii_lowercase();
            let same = origin
                .strip_prefix("http://")
                .is_some_and(|o| o == host.trim().to_ascii_lowercase());
            if !same {
                return Err(Refusal(
                    403,
                    format!("Origin {origin:?} is not this daemon's own; cross-site requests are refused"),
                ));
            }
        }
        Ok(())
    }
}

/// "name:port" → (name, port); an IPv6 literal keeps its brackets. None if malformed.
fn split_host_port(host: &str) -> Option<(&str, Option<u16>)> {
    if host.is_empty() {
        return None;
    }
    if let Some(rest) = host.strip_prefix('[') {
        let end = rest.find(']')?;
        let name = &host[..end + 2];
        return match &rest[end + 1..] {
            "" => Some((name, None)),
            p => Some((name, Some(p.strip_prefix(':')?.parse().ok()?))),
        };
    }
    match host.rsplit_once(':') {
        Some((name, port)) => Some((name, Some(port.parse().ok()?))),
        None => Some((host, None)),
    }
}

/// The value of cookie `name` in the request's Cookie headers.
fn cookie<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().split_once('='))
        .find(|(k, _)| *k == name)
        .map(|(_, v)| v)
}

/// Compares without returning early on the first difference, so the time taken does not tell
/// an attacker how much of a guess was right (the length is not secret: ≥ 16 is public).
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = (a.len() ^ b.len()) as u64;
    for i in 0..a.len().max(b.len()) {
        let x = a.get(i).copied().unwrap_or(0);
        let y = b.get(i).copied().unwrap_or(0);
        diff |= u64::from(x ^ y);
    }
    // black_box keeps the optimiser from turning the loop back into an early exit.
    std::hint::black_box(diff) == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(*k, HeaderValue::from_str(v).unwrap());
        }
        h
    }

    fn loopback() -> RequestGuard {
        RequestGuard::new("127.0.0.1:8620".parse().unwrap(), &[], None)
    }

    #[test]
    fn host_must_name_this_daemon() {
        let g = loopback();
        assert!(g.host_allowed("127.0.0.1:8620"));
        assert!(g.host_allowed("LOCALHOST:8620"));
        assert!(g.host_allowed("[::1]:8620"));
        assert!(!g.host_allowed("evil.example:8620"));
        assert!(!g.host_allowed("127.0.0.1:8621"));
        assert!(!g.host_allowed("127.0.0.1"));
        assert!(!g.host_allowed(""));
        let named = RequestGuard::new(
            "0.0.0.0:80".parse().unwrap(),
            &["LabPC.local".into()],
            Some("0123456789abcdef".into()),
        );
        assert!(named.host_allowed("labpc.local:80"));
        assert!(named.host_allowed("192.168.1.20:80"));
        assert!(!named.host_allowed("evil.example:80"));
    }

    #[test]
    fn state_changes_need_json_and_no_foreign_origin() {
        let g = loopback();
        let host = ("host", "127.0.0.1:8620");
        let post = Method::POST;
        assert_eq!(
            g.check(&post, &headers(&[host, ("content-type", "text/plain")]))
                .unwrap_err()
                .0,
            415
        );
        assert_eq!(g.check(&post, &headers(&[host])).unwrap_err().0, 415);
        assert_eq!(
            g.check(
                &post,
                &headers(&[host, ("content-type", "application/x-www-form-urlencoded")])
            )
            .unwrap_err()
            .0,
            415
        );
        let json = ("content-type", "Application/JSON; charset=utf-8");
        assert!(g.check(&post, &headers(&[host, json])).is_ok());
        assert!(g
            .check(
                &post,
                &headers(&[host, json, ("origin", "http://127.0.0.1:8620")])
            )
            .is_ok());
        assert_eq!(
            g.check(
                &post,
                &headers(&[host, json, ("origin", "http://evil.example")])
            )
            .unwrap_err()
            .0,
            403
        );
        assert_eq!(
            g.check(&post, &headers(&[host, json, ("origin", "null")]))
                .unwrap_err()
                .0,
            403
        );
        assert_eq!(
            g.check(&Method::GET, &headers(&[("host", "evil.example:8620")]))
                .unwrap_err()
                .0,
            421
        );
        assert!(g.check(&Method::GET, &headers(&[host])).is_ok());
    }

    #[test]
    fn token_by_bearer_in_any_case_or_cookie() {
        let g = RequestGuard::new(
            "127.0.0.1:1".parse().unwrap(),
            &[],
            Some("0123456789abcdef-x".into()),
        );
        assert!(!g.authorised(&headers(&[])));
        assert!(g.authorised(&headers(&[("authorization", "bearer 0123456789abcdef-x")])));
        assert!(g.authorised(&headers(&[("authorization", "BEARER 0123456789abcdef-x")])));
        assert!(!g.authorised(&headers(&[("authorization", "Bearer 0123456789abcdef-y")])));
        assert!(!g.authorised(&headers(&[("authorization", "Bearer 0123456789abcdef")])));
        assert!(g.authorised(&headers(&[(
            "cookie",
            "a=b; impactcam_token=0123456789abcdef-x"
        )])));
        assert!(!g.authorised(&headers(&[("cookie", "impactcam_token=nope")])));
    }

    #[test]
    fn constant_time_eq_is_equality() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"abcd"));
        assert!(!constant_time_eq(b"", b"a"));
        assert!(constant_time_eq(b"", b""));
    }
}
