//! How a coordinator finds its workers: a static list of URLs, DNS names re-resolved
//! periodically (a Kubernetes headless Service gives one address per ready pod), and
//! workers that register themselves (see [`super::registry`]).

use super::pool::{Origin, WorkerPool};
use std::future::Future;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Weak};
use std::time::Duration;

/// Addresses a name resolves to, or why it does not.
pub type Resolution = Pin<Box<dyn Future<Output = std::io::Result<Vec<SocketAddr>>> + Send>>;

/// Turns `name:port` into socket addresses: the system's resolver, or one a test controls.
pub trait Resolve: Send + Sync + 'static {
    fn resolve(&self, name: &str) -> Resolution;
}

/// The operating system's resolver (`getaddrinfo`, as `tokio::net::lookup_host`).
#[derive(Debug, Default, Clone, Copy)]
pub struct SystemResolver;

impl Resolve for SystemResolver {
    fn resolve(&self, name: &str) -> Resolution {
        let name = name.to_string();
        Box::pin(async move { Ok(tokio::net::lookup_host(name).await?.collect()) })
    }
}

/// The resolver a pool uses for `dns:///` workers.
#[derive(Clone)]
pub struct Resolver(pub Arc<dyn Resolve>);

impl Default for Resolver {
    fn default() -> Self {
        Self(Arc::new(SystemResolver))
    }
}

impl std::fmt::Debug for Resolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Resolver")
    }
}

/// One entry of a `--workers` list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WorkerAddress {
    /// `http://host:port` or `https://host:port`: one worker.
    Url(String),
    /// `dns:///name:port`: every address `name` resolves to, re-resolved periodically;
    /// dialed over TLS, verified as `name`, when the pool trusts a CA of its own.
    Dns { host: String, port: u16 },
}

impl std::str::FromStr for WorkerAddress {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if let Some(rest) = text.strip_prefix("dns://") {
            // `dns:///name:port`, or `dns://authority/name:port` with the authority ignored.
            let target = rest.split_once('/').map_or(rest, |(_, t)| t);
            let (host, port) = target
                .rsplit_once(':')
                .ok_or_else(|| format!("`{text}`: expected dns:///NAME:PORT"))?;
            let port: u16 = port
                .parse()
                .map_err(|_| format!("`{text}`: `{port}` is not a port number"))?;
            if host.is_empty() {
                return Err(format!("`{text}`: no name to resolve"));
            }
            return Ok(WorkerAddress::Dns {
                host: host.to_string(),
                port,
            });
        }
        let scheme = ["http://", "https://"]
            .into_iter()
            .find_map(|scheme| text.strip_prefix(scheme).map(|rest| (scheme, rest)));
        if let Some((scheme, rest)) = scheme {
            let authority = rest.split('/').next().unwrap_or_default();
            let has_port = authority
                .rsplit_once(':')
                .is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok());
            if !has_port {
                return Err(format!("`{text}`: expected {scheme}HOST:PORT"));
            }
            return Ok(WorkerAddress::Url(text.trim_end_matches('/').to_string()));
        }
        Err(format!(
            "`{text}`: a worker is http://HOST:PORT, https://HOST:PORT or dns:///NAME:PORT"
        ))
    }
}

/// Parse a comma-separated `--workers` list.
pub fn parse_list(list: &str) -> Result<Vec<WorkerAddress>, String> {
    list.split(',')
        .filter(|s| !s.trim().is_empty())
        .map(str::parse)
        .collect()
}

/// Put every address in `pool`: URLs at once, DNS names by a task that re-resolves them.
pub fn discover(pool: &Arc<WorkerPool>, addresses: &[WorkerAddress]) -> Result<(), String> {
    for address in addresses {
        match address {
            WorkerAddress::Url(url) => pool.add(url, Origin::Static)?,
            WorkerAddress::Dns { host, port } => {
                tokio::spawn(resolve_forever(
                    Arc::downgrade(pool),
                    pool.config().resolver.clone(),
                    format!("{host}:{port}"),
                    pool.config().resolve_interval,
                ));
            }
        }
    }
    Ok(())
}

/// Keep the pool's workers from `name` (`host:port`) equal to what it resolves to: new
/// addresses join, vanished ones leave; a failed resolution changes nothing.
async fn resolve_forever(
    pool: Weak<WorkerPool>,
    resolver: Resolver,
    name: String,
    every: Duration,
) {
    let mut ticker = tokio::time::interval(every);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        ticker.tick().await;
        let resolved = resolver.0.resolve(&name).await;
        let Some(pool) = pool.upgrade() else { return };
        let addresses = match resolved {
            Ok(addresses) => addresses,
            Err(e) => {
                // Keep the workers we have: a DNS hiccup is no reason to stop.
                tracing::warn!(name = %name, error = %e, "cannot resolve workers");
                continue;
            }
        };
        let scheme = if pool.config().security.ca.is_some() {
            "https"
        } else {
            "http"
        };
        let mut urls: Vec<String> = addresses
            .into_iter()
            .map(|a| format!("{scheme}://{a}"))
            .collect();
        urls.sort();
        urls.dedup();
        for stale in pool.urls_from(&name) {
            if !urls.contains(&stale) {
                pool.remove(&stale);
            }
        }
        for url in &urls {
            if let Err(e) = pool.add(url, Origin::Dns(name.clone())) {
                tracing::warn!(worker = %url, error = %e, "cannot add resolved worker");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form() {
        assert_eq!(
            parse_list("http://a:1, http://b:2/,dns:///w.default.svc:50051,https://c:3").unwrap(),
            vec![
                WorkerAddress::Url("http://a:1".into()),
                WorkerAddress::Url("http://b:2".into()),
                WorkerAddress::Dns {
                    host: "w.default.svc".into(),
                    port: 50051
                },
                WorkerAddress::Url("https://c:3".into()),
            ]
        );
        assert_eq!(
            "dns://8.8.8.8/w:7".parse::<WorkerAddress>().unwrap(),
            WorkerAddress::Dns {
                host: "w".into(),
                port: 7
            }
        );
    }

    #[test]
    fn rejects_what_is_not_a_worker() {
        for bad in [
            "a:1",
            "http://a",
            "dns:///w",
            "dns:///:5",
            "http://:5",
            "tcp://a:1",
            "https://a",
        ] {
            assert!(bad.parse::<WorkerAddress>().is_err(), "{bad}");
        }
    }
}
