//! A worker announcing itself to a coordinator's Registry, again every heartbeat.

use calib_proto::v1 as proto;
use std::net::SocketAddr;
use std::time::Duration;

/// Wait after a failed registration before the next attempt.
const RETRY: Duration = Duration::from_secs(2);

/// The URL a coordinator can reach this worker at: the bound address, or this host's name
/// when bound to every interface (in a Kubernetes pod the name resolves to the pod's IP).
pub fn advertised_url(bound: SocketAddr) -> String {
    if !bound.ip().is_unspecified() {
        return format!("http://{bound}");
    }
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into());
    format!("http://{host}:{}", bound.port())
}

/// Register `advertised` with the coordinator at `coordinator`, forever.
pub async fn heartbeat(coordinator: String, advertised: String) {
    let mut registered = false;
    loop {
        let wait = match register_once(&coordinator, &advertised).await {
            Ok(heartbeat) => {
                if !registered {
                    tracing::info!(%coordinator, worker = %advertised, "registered with the coordinator");
                    registered = true;
                }
                heartbeat
            }
            Err(e) => {
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

async fn register_once(coordinator: &str, advertised: &str) -> Result<Duration, String> {
    let channel = tonic::transport::Endpoint::from_shared(coordinator.to_string())
        .map_err(|e| e.to_string())?
        .connect_timeout(Duration::from_secs(5))
        .timeout(Duration::from_secs(5))
        .connect()
        .await
        .map_err(|e| e.to_string())?;
    let answer = proto::registry_client::RegistryClient::new(channel)
        .register(proto::RegisterRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            address: advertised.to_string(),
        })
        .await
        .map_err(|e| e.message().to_string())?;
    Ok(Duration::from_secs(u64::from(
        answer.into_inner().heartbeat_seconds.max(1),
    )))
}
