//! `calib health URL`: ask a worker or coordinator's gRPC health service whether it serves,
//! for container healthchecks and scripts (Kubernetes probes speak gRPC health natively).

use super::{Failure, Outcome};
use std::time::Duration;
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;
use tonic_health::pb::HealthCheckRequest;

#[derive(clap::Args)]
pub struct Args {
    /// The server to ask: http://HOST:PORT, or https://HOST:PORT (trusting --tls-ca).
    #[arg(value_name = "URL")]
    url: String,
    /// The service to ask about (e.g. calib.v1.Simulator, calib.v1.Calibration)
    /// [default: the server as a whole].
    #[arg(long, default_value = "", hide_default_value = true)]
    service: String,
    /// Seconds to wait for the answer, connecting included.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    timeout: f64,
    /// For https://: the name the server's certificate must carry [default: the URL's host]
    /// (a probe dialing 127.0.0.1 inside a pod checks the certificate issued for its
    /// Service's name).
    #[arg(long, value_name = "NAME")]
    server_name: Option<String>,
    #[command(flatten)]
    dial: super::security::DialArgs,
}

/// Exit 0 and print `SERVING` when the server says it serves; exit 1 otherwise.
pub fn run(args: Args) -> Outcome {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(Failure::input(
            "--timeout: must be a finite number of seconds above 0",
        ));
    }
    let timeout = Duration::from_secs_f64(args.timeout);
    let security = args.dial.client()?;
    let endpoint = security
        .endpoint(&args.url, args.server_name.as_deref())
        .map_err(|e| Failure::input(format!("URL: {e}")))?
        .connect_timeout(timeout)
        .timeout(timeout);
    let runtime = super::runtime()?;
    let answer = runtime.block_on(async {
        let channel = endpoint
            .connect()
            .await
            .map_err(|e| format!("{}: cannot connect: {}", args.url, causes(&e)))?;
        HealthClient::new(security.authorize(channel))
            .check(HealthCheckRequest {
                service: args.service.clone(),
            })
            .await
            .map(|r| r.into_inner().status)
            .map_err(|s| format!("{}: {:?}: {}", args.url, s.code(), s.message()))
    });
    let status = answer.map_err(Failure::internal)?;
    let name = ServingStatus::try_from(status)
        .map(|s| s.as_str_name())
        .unwrap_or("UNKNOWN");
    println!("{name}");
    if status == ServingStatus::Serving as i32 {
        Ok(())
    } else {
        Err(Failure::internal(format!(
            "{}: {} is {name}",
            args.url,
            if args.service.is_empty() {
                "the server"
            } else {
                &args.service
            }
        )))
    }
}

/// An error and its causes, as one line.
fn causes(error: &(dyn std::error::Error + 'static)) -> String {
    let mut line = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        line.push_str(": ");
        line.push_str(&cause.to_string());
        source = cause.source();
    }
    line
}
