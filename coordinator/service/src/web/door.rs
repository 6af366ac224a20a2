//! The web app's door: which requests reach its routes.
//!
//! - **Host** (every route): the `Host` header must name this server as it was bound (its
//!   address, `localhost`, `127.0.0.1` or `[::1]` with its port; any IP address with its
//!   port when bound to all interfaces) or a name given with `--allow-host`. A page served
//!   from another name, even one that resolves here (DNS rebinding), gets 403, so it can
//!   neither call the app nor read its answers.
//! - **Same origin** (`/api/`, `/ui/`, `/login`, `/logout`): a request that says where it
//!   comes from (`Origin`, `Sec-Fetch-Site`) must come from the page this server serves; any
//!   other web page gets 403 whatever it sends, a `text/plain` form post included. Programs
//!   (curl, the Python client) send neither header and pass.
//! - **Login** (`/api/`, `/ui/`, on a server with a token): the cluster's bearer token in
//!   `authorization: Bearer …`, or the session cookie `/login` sets after checking that
//!   token. The cookie holds a session key drawn for that login, never the token, kept on
//!   the server until it expires or `/logout` revokes it ([`super::login`]); it is
//!   `HttpOnly` (no script reads it), `SameSite=Strict`, `Secure` when the page came over
//!   HTTPS (through a proxy), and the same-origin check above keeps other pages from using
//!   it. Wrong tokens are throttled per client address ([`super::login::Throttle`]).
//!   Without a token everything passes (`calib ui` on its own machine). The page itself
//!   (`/`, `/js/…`, `/app.css`) needs no login.

use super::login::{Sessions, Throttle, SESSION_LIFETIME};
use super::ApiError;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use calib_security::Token;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tonic::Status;

/// Who may come in: names besides the bound address, and the token when there is one.
#[derive(Debug, Clone, Default)]
pub struct DoorConfig {
    /// Host names (or `name:port`) the app also answers as (`--allow-host`): a reverse
    /// proxy's name, the machine's name on the network.
    pub allow_hosts: Vec<String>,
    /// The cluster's token: required on every `/api/` and `/ui/` route when set.
    pub token: Option<Token>,
}

/// A host name `--allow-host` accepts, lowercase: `name` or `name:port`.
pub fn parse_allowed_host(text: &str) -> Result<String, String> {
    let host = text.trim().to_ascii_lowercase();
    let valid = !host.is_empty()
        && host
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b':' | b'[' | b']'));
    if !valid {
        return Err(format!(
            "`{text}` is not a host name (a name or an address, with `:port` or without; \
             no scheme, no path)"
        ));
    }
    Ok(host)
}

/// The door of one server: [`DoorConfig`] and the address it was bound to.
#[derive(Debug)]
pub struct Door {
    bound: SocketAddr,
    allow_hosts: Vec<String>,
    token: Option<Token>,
    /// The sessions logins opened.
    sessions: Mutex<Sessions>,
    /// Wrong tokens per client address.
    throttle: Mutex<Throttle>,
    cookie: String,
}

/// What a request is refused with.
struct Refusal(Status);

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        let code = self.0.code();
        let retry = self
            .0
            .metadata()
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| header::HeaderValue::from_str(v).ok());
        let mut response = ApiError::from(self.0).into_response();
        if code == tonic::Code::Unauthenticated {
            response.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                header::HeaderValue::from_static("Bearer"),
            );
        }
        if let Some(seconds) = retry {
            response.headers_mut().insert(header::RETRY_AFTER, seconds);
        }
        response
    }
}

/// The address a request came from (unspecified when the server was not told).
fn client(request: &Request) -> IpAddr {
    request
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |c| c.0.ip())
}

/// Whether a token was presented, and whether it was the server's.
enum Presented {
    Nothing,
    Right,
    Wrong,
}

impl Door {
    pub fn new(config: DoorConfig, bound: SocketAddr) -> Self {
        Self {
            bound,
            allow_hosts: config.allow_hosts,
            token: config.token,
            sessions: Mutex::default(),
            throttle: Mutex::default(),
            // One name per port: browsers share cookies between the ports of a host.
            cookie: format!("calib_session_{}", bound.port()),
        }
    }

    /// Refuse the request, or let it through.
    fn admit(&self, request: &Request) -> Result<(), Refusal> {
        let headers = request.headers();
        let host = self.check_host(request)?;
        let path = request.uri().path();
        let guarded = path.starts_with("/api/") || path.starts_with("/ui/");
        if guarded || path == "/login" || path == "/logout" {
            same_origin(headers, &host)?;
        }
        if !guarded || self.token.is_none() || self.has_session(headers) {
            return Ok(());
        }
        match self.check_bearer(headers, client(request))? {
            Presented::Right => Ok(()),
            Presented::Nothing | Presented::Wrong => Err(Refusal(Status::unauthenticated(
                "this server requires the cluster's token: sign in on the page, or send \
                 `authorization: Bearer <token>`",
            ))),
        }
    }

    /// The bearer token `headers` present, judged: refused unread while `address` is closed
    /// for its wrong tokens, and counted for or against it.
    fn check_bearer(&self, headers: &HeaderMap, address: IpAddr) -> Result<Presented, Refusal> {
        let Some(token) = &self.token else {
            return Ok(Presented::Right);
        };
        let Some(value) = headers.get(header::AUTHORIZATION) else {
            return Ok(Presented::Nothing);
        };
        let now = Instant::now();
        let mut throttle = self.throttle.lock().expect("throttle lock");
        if let Some(wait) = throttle.closed(address, now) {
            return Err(too_many(wait));
        }
        if token.matches(calib_security::token::bearer(value.as_bytes())) {
            throttle.succeeded(address);
            return Ok(Presented::Right);
        }
        let closed = throttle.failed(address, now);
        drop(throttle);
        tracing::warn!(%address, closed_for_s = closed.map_or(0, |d| d.as_secs()), "web request with a wrong token");
        Ok(Presented::Wrong)
    }

    /// The request's `Host`, if it names this server.
    fn check_host(&self, request: &Request) -> Result<String, Refusal> {
        let host = request
            .headers()
            .get(header::HOST)
            .and_then(|h| h.to_str().ok())
            .map(str::to_string)
            .or_else(|| request.uri().authority().map(|a| a.to_string()))
            .ok_or_else(|| Refusal(Status::permission_denied("the request names no Host")))?;
        if self.host_allowed(&host) {
            Ok(host)
        } else {
            Err(Refusal(Status::permission_denied(format!(
                "Host `{host}` is not a name this server answers as (its address, localhost \
                 with its port {port}); start it with --allow-host NAME to answer as another",
                port = self.bound.port()
            ))))
        }
    }

    fn host_allowed(&self, host: &str) -> bool {
        let host = host.to_ascii_lowercase();
        let Some((name, port)) = split_host(&host) else {
            return false;
        };
        let named = self
            .allow_hosts
            .iter()
            .any(|allowed| allowed == &host || allowed == name);
        if named {
            return true;
        }
        if port.unwrap_or(80) != self.bound.port() {
            return false;
        }
        if name == "localhost" {
            return true;
        }
        let Ok(ip) = name
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<IpAddr>()
        else {
            return false;
        };
        ip == self.bound.ip() || ip.is_loopback() || self.bound.ip().is_unspecified()
    }

    /// The session keys the request's cookies hold under this server's cookie name.
    fn session_keys<'h>(&self, headers: &'h HeaderMap) -> impl Iterator<Item = &'h str> + 'h {
        let name = self.cookie.clone();
        headers
            .get_all(header::COOKIE)
            .iter()
            .filter_map(|value| value.to_str().ok())
            .flat_map(|value| value.split(';'))
            .filter_map(|pair| pair.trim().split_once('='))
            .filter(move |(n, _)| *n == name)
            .map(|(_, value)| value)
    }

    /// Whether the request holds a session this server keeps.
    fn has_session(&self, headers: &HeaderMap) -> bool {
        let now = Instant::now();
        let sessions = self.sessions.lock().expect("sessions lock");
        self.session_keys(headers).any(|k| sessions.valid(k, now))
    }

    /// A new session's cookie; `Secure` when the page that asked came over HTTPS.
    fn session_cookie(&self, secure: bool) -> String {
        let key = self
            .sessions
            .lock()
            .expect("sessions lock")
            .open(Instant::now());
        format!(
            "{}={key}; HttpOnly; SameSite=Strict; Path=/; Max-Age={}{}",
            self.cookie,
            SESSION_LIFETIME.as_secs(),
            if secure { "; Secure" } else { "" }
        )
    }
}

/// 429 for an address closed for `wait` more.
fn too_many(wait: Duration) -> Refusal {
    let seconds = wait.as_secs() + u64::from(wait.subsec_nanos() > 0);
    let mut status = Status::resource_exhausted(format!(
        "too many wrong tokens from this address: try again in {seconds} s"
    ));
    if let Ok(value) = seconds.to_string().parse() {
        status.metadata_mut().insert("retry-after", value);
    }
    Refusal(status)
}

/// Whether the page asking came over HTTPS (a TLS proxy in front of the app): its `Origin`,
/// or the proxy's `X-Forwarded-Proto`.
fn over_https(headers: &HeaderMap) -> bool {
    let says = |name: &str, https: &str| {
        headers
            .get(name)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|v| v.to_ascii_lowercase().starts_with(https))
    };
    says("origin", "https://") || says("x-forwarded-proto", "https")
}

/// `name` and `port` of a Host header (`name`, `name:port`, `[v6]`, `[v6]:port`).
fn split_host(host: &str) -> Option<(&str, Option<u16>)> {
    let (name, port) = if host.starts_with('[') {
        let end = host.find(']')? + 1;
        match &host[end..] {
            "" => (&host[..end], None),
            rest => (&host[..end], Some(rest.strip_prefix(':')?)),
        }
    } else {
        match host.split_once(':') {
            Some((name, port)) => (name, Some(port)),
            None => (host, None),
        }
    };
    if name.is_empty() {
        return None;
    }
    match port {
        Some(port) => Some((name, Some(port.parse().ok()?))),
        None => Some((name, None)),
    }
}

/// Refuses a request another web page sent: its `Origin` (when there is one) must be this
/// server as the browser reached it, and its `Sec-Fetch-Site` (when there is one) must say
/// the same origin, or a request the user typed.
fn same_origin(headers: &HeaderMap, host: &str) -> Result<(), Refusal> {
    if let Some(site) = headers.get("sec-fetch-site") {
        let site = site.to_str().unwrap_or("");
        if site != "same-origin" && site != "none" {
            return Err(Refusal(Status::permission_denied(format!(
                "requests from other web pages are refused (Sec-Fetch-Site: {site}); use the \
                 page this server serves"
            ))));
        }
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("");
        let authority = origin
            .strip_prefix("http://")
            .or_else(|| origin.strip_prefix("https://"));
        if !authority.is_some_and(|a| a.eq_ignore_ascii_case(host)) {
            return Err(Refusal(Status::permission_denied(format!(
                "requests from other web pages are refused (Origin `{origin}` is not \
                 http://{host}); use the page this server serves"
            ))));
        }
    }
    Ok(())
}

/// The door in front of every route.
pub async fn guard(State(door): State<Arc<Door>>, request: Request, next: Next) -> Response {
    match door.admit(&request) {
        Ok(()) => next.run(request).await,
        Err(refusal) => {
            tracing::debug!(path = %request.uri().path(), reason = %refusal.0.message(), "web request refused");
            refusal.into_response()
        }
    }
}

/// `GET /login`: whether this server requires a login and whether the browser has one.
pub async fn login_state(State(door): State<Arc<Door>>, headers: HeaderMap) -> Response {
    let state = serde_json::json!({
        "required": door.token.is_some(),
        "signed_in": door.token.is_none() || door.has_session(&headers),
    });
    (
        [(header::CONTENT_TYPE, "application/json")],
        state.to_string(),
    )
        .into_response()
}

/// `POST /login` with `authorization: Bearer <token>`: a new session's cookie when the
/// token is the server's (compared in constant time), 401 otherwise, and 429 while the
/// client's address is closed for its wrong tokens.
pub async fn login(State(door): State<Arc<Door>>, request: Request) -> Response {
    if door.token.is_none() {
        return StatusCode::NO_CONTENT.into_response();
    }
    let headers = request.headers();
    match door.check_bearer(headers, client(&request)) {
        Err(refusal) => refusal.into_response(),
        Ok(Presented::Right) => (
            StatusCode::NO_CONTENT,
            [(header::SET_COOKIE, door.session_cookie(over_https(headers)))],
        )
            .into_response(),
        Ok(Presented::Nothing | Presented::Wrong) => {
            Refusal(Status::unauthenticated("the token is not this server's")).into_response()
        }
    }
}

/// `POST /logout`: end the session the browser holds, on the server and in the browser.
pub async fn logout(State(door): State<Arc<Door>>, headers: HeaderMap) -> Response {
    {
        let mut sessions = door.sessions.lock().expect("sessions lock");
        for key in door.session_keys(&headers) {
            sessions.revoke(key);
        }
    }
    (
        StatusCode::NO_CONTENT,
        [(
            header::SET_COOKIE,
            format!(
                "{}=; HttpOnly; SameSite=Strict; Path=/; Max-Age=0",
                door.cookie
            ),
        )],
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn door(bound: &str, allow: &[&str]) -> Door {
        Door::new(
            DoorConfig {
                allow_hosts: allow
                    .iter()
                    .map(|h| parse_allowed_host(h).unwrap())
                    .collect(),
                token: None,
            },
            bound.parse().unwrap(),
        )
    }

    #[test]
    fn hosts_are_the_bound_address_loopback_names_and_the_allowed() {
        let local = door("127.0.0.1:8080", &["calib.lab", "proxy.example:443"]);
        for host in [
            "127.0.0.1:8080",
            "localhost:8080",
            "LOCALHOST:8080",
            "[::1]:8080",
            "calib.lab",
            "calib.lab:9999",
            "proxy.example:443",
        ] {
            assert!(local.host_allowed(host), "{host}");
        }
        for host in [
            "evil.example:8080",
            "127.0.0.1:8081",
            "localhost",
            "10.0.0.5:8080",
            "proxy.example:444",
            "proxy.example",
            "localhost.evil.example:8080",
            ":8080",
            "[::1:8080",
            "localhost:80x",
        ] {
            assert!(!local.host_allowed(host), "{host}");
        }
        let everywhere = door("0.0.0.0:8080", &[]);
        assert!(everywhere.host_allowed("10.0.0.5:8080"));
        assert!(everywhere.host_allowed("[fe80::1]:8080"));
        assert!(!everywhere.host_allowed("rebound.evil.example:8080"));
    }

    #[test]
    fn allowed_hosts_are_names_not_urls() {
        assert_eq!(parse_allowed_host(" Calib.Lab ").unwrap(), "calib.lab");
        for bad in ["", "http://x", "x/y", "a b"] {
            assert!(parse_allowed_host(bad).is_err(), "{bad:?}");
        }
    }
}
