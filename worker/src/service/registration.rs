//! A worker announcing itself to a coordinator's Registry, again every heartbeat.

use calib_proto::v1 as proto;
use calib_security::ClientSecurity;
use std::net::SocketAddr;
use std::time::Duration;

/// Wait after a failed registration before the next attempt.
const RETRY: Duration = Duration::from_secs(2);

/// The URL a coordinator can reach this worker at (`scheme` `http` or `https`): the bound
/// address, or this host's name when bound to every interface (in a Kubernetes pod the
/// name resolves to the pod's IP).
pub fn advertised_url(bound: SocketAddr, scheme: &str) -> String {
    if !bound.ip().is_unspecified() {
        return format!("{scheme}://{bound}");
    }
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into());
    format!("{scheme}://{host}:{}", bound.port())
}

/// Register `advertised` with the coordinator at `coordinator`, forever. A refused token or
/// certificate is logged as an error each time it changes: it will not heal by itself.
pub async fn heartbeat(coordinator: String, advertised: String, security: ClientSecurity) {
    let mut registered = false;
    let mut last_refusal: Option<String> = None;
    loop {
        let wait = match register_once(&coordinator, &advertised, &security).await {
            Ok(heartbeat) => {
                if !registered {
                    tracing::info!(%coordinator, worker = %advertised, "registered with the coordinator");
                    registered = true;
                }
                last_refusal = None;
                heartbeat
            }
            Err(Failure::Refused(reason)) => {
                if last_refusal.as_deref() != Some(reason.as_str()) {
                    tracing::error!(%coordinator, error = %reason, "the coordinator cannot be trusted or refuses this worker");
                    last_refusal = Some(reason);
                }
                registered = false;
                RETRY
            }
            Err(Failure::Other(e)) => {
                if registered {
                    tracing::warn!(%coordinator, error = %e, "registration lost");
                    registered = false;
                } else {
                    tracing::debug!(%coordinator, error = %e, "registration failed");
                }
                RETRY
            }
        };
        tokio::time::sleep(wait).await;
    }
}

enum Failure {
    /// A certificate or token refused: configuration, not chance.
    Refused(String),
    Other(String),
}

impl From<tonic::Status> for Failure {
    fn from(status: tonic::Status) -> Self {
        match calib_security::failure::refusal(&status) {
            Some(reason) => Failure::Refused(reason),
            // The coordinator will not dial the advertised address (a token over plain
            // http to another machine, a malformed URL): asking again changes nothing.
            None if status.code() == tonic::Code::InvalidArgument => Failure::Refused(format!(
                "the coordinator refuses this worker's registration: {}",
                status.message()
            )),
            None => Failure::Other(status.message().to_string()),
        }
    }
}

async fn register_once(
    coordinator: &str,
    advertised: &str,
    security: &ClientSecurity,
) -> Result<Duration, Failure> {
    let channel = security
        .endpoint(coordinator, None)
        .map_err(|e| Failure::Refused(e.to_string()))?
        .connect_timeout(Duration::from_secs(5))
        .timeout(Duration::from_secs(5))
        .connect()
        .await
        .map_err(|e| match calib_security::failure::tls_failure(&e) {
            Some(reason) => Failure::Refused(reason),
            None => Failure::Other(e.to_string()),
        })?;
    let answer = proto::registry_client::RegistryClient::new(security.authorize(channel))
        .register(proto::RegisterRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            address: advertised.to_string(),
        })
        .await?;
    Ok(Duration::from_secs(u64::from(
        answer.into_inner().heartbeat_seconds.max(1),
    )))
}
