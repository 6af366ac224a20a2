use super::{Failure, Outcome};
use calib_worker::service::{self, WorkerConfig};
use std::net::SocketAddr;

#[derive(clap::Args)]
pub struct Args {
    /// Address to serve the Simulator service on (port 0: any free port, printed).
    #[arg(long, default_value = "0.0.0.0:50051")]
    listen: SocketAddr,
    /// Simulations at once [default: one per core].
    #[arg(long)]
    slots: Option<usize>,
    /// Simulations that may wait for a slot before requests are refused with
    /// RESOURCE_EXHAUSTED [default: 64 per slot].
    #[arg(long)]
    queue: Option<usize>,
    /// Bound of the measurement cache [MiB].
    #[arg(long, default_value_t = 256)]
    cache_mib: usize,
    /// Register with the coordinator at this URL (e.g. http://coordinator:50050, or
    /// https:// with --tls-ca) and renew the registration as a heartbeat.
    #[arg(long, value_name = "URL")]
    register: Option<String>,
    /// URL the coordinator should dial back [default: the bound address, or this host's
    /// name when listening on every interface; https:// with --tls-cert].
    #[arg(long, value_name = "URL")]
    advertise: Option<String>,
    /// Accept FMUs (models users bring). Loading one runs its native code: each FMU
    /// instance then runs in a child process per slot, with a deadline. Without this flag
    /// FMUs are refused with PERMISSION_DENIED.
    #[arg(long)]
    allow_fmu: bool,
    /// Folder of the cache of uploaded FMUs [default: calib-fmu-cache in the temporary
    /// folder].
    #[arg(long, value_name = "DIR", requires = "allow_fmu")]
    fmu_cache: Option<std::path::PathBuf>,
    /// Bound of the FMU cache [MiB]; the least recently used go first.
    #[arg(long, default_value_t = 1024, requires = "allow_fmu")]
    fmu_cache_mib: u64,
    #[command(flatten)]
    serve: super::security::ServeArgs,
    #[command(flatten)]
    dial: super::security::DialArgs,
}

pub fn run(args: Args) -> Outcome {
    let mut config = WorkerConfig::new(args.listen);
    if let Some(slots) = args.slots {
        if slots == 0 {
            return Err(Failure::input("--slots: must be at least 1"));
        }
        config.slots = slots;
        config.queue_bound = 64 * slots;
    }
    if let Some(queue) = args.queue {
        config.queue_bound = queue;
    }
    config.cache_bytes = args.cache_mib << 20;
    if args.allow_fmu {
        let dir = args
            .fmu_cache
            .unwrap_or_else(|| std::env::temp_dir().join("calib-fmu-cache"));
        config.fmu_cache = Some((dir, args.fmu_cache_mib << 20));
    }
    config.register = args.register;
    config.advertise = args.advertise;
    config.security = args.serve.server(&args.dial)?;
    config.register_security = args.dial.client()?;
    if let Some(warning) = fmu_warning(
        args.allow_fmu,
        config.security.token.is_some(),
        &args.listen,
    ) {
        eprintln!("{warning}");
    }
    if let Some(coordinator) = &config.register {
        // Refused now (a token over plain http to another machine) rather than at every
        // heartbeat.
        config
            .register_security
            .endpoint(coordinator, None)
            .map_err(|e| Failure::input(format!("--register {e}")))?;
    }
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let worker = service::start_worker(config.clone()).await.map_err(|e| {
            Failure::internal(format!("--listen {}: cannot listen: {e}", config.listen))
        })?;
        println!(
            "worker listening on {} ({} slots, queue bound {})",
            worker.address(),
            config.slots,
            config.queue_bound
        );
        worker
            .serve_until(super::terminated())
            .await
            .map_err(|e| Failure::internal(format!("worker server failed: {e}")))
    })
}

/// What to say about accepting FMUs (native code) on `listen`, with or without a token.
fn fmu_warning(allow_fmu: bool, token: bool, listen: &SocketAddr) -> Option<String> {
    if !allow_fmu {
        return None;
    }
    #[cfg(target_os = "linux")]
    let contained = calib_model::fmu::contain::containment().to_string();
    #[cfg(not(target_os = "linux"))]
    let contained = "each FMU runs in a child process with a deadline".to_string();
    if token {
        return Some(format!("calib worker: --allow-fmu: {contained}"));
    }
    if listen.ip().is_loopback() {
        return Some(format!(
            "calib worker: WARNING: --allow-fmu without --token-file: any program on this \
             machine may upload an FMU and run its native code as this user; {contained}"
        ));
    }
    let rule = "!".repeat(78);
    Some(format!(
        "{rule}\ncalib worker: WARNING: --allow-fmu WITHOUT A TOKEN ON {listen}, NOT LOOPBACK:\n\
         ANYONE WHO CAN REACH THIS ADDRESS MAY RUN NATIVE CODE HERE AS THIS USER.\n\
         Give a --token-file (and --tls-cert/--tls-key), or --listen 127.0.0.1:PORT.\n\
         {contained}\n{rule}"
    ))
}

#[cfg(test)]
mod tests {
    use super::fmu_warning;

    #[test]
    fn accepting_fmus_without_a_token_is_warned_of_loudly_off_loopback() {
        let any = "0.0.0.0:50051".parse().unwrap();
        let local = "127.0.0.1:50051".parse().unwrap();
        assert_eq!(fmu_warning(false, false, &any), None);
        let loud = fmu_warning(true, false, &any).unwrap();
        assert!(
            loud.contains("WITHOUT A TOKEN ON 0.0.0.0:50051, NOT LOOPBACK"),
            "{loud}"
        );
        let quiet = fmu_warning(true, false, &local).unwrap();
        assert!(
            quiet.contains("WARNING: --allow-fmu without --token-file"),
            "{quiet}"
        );
        assert!(!quiet.contains("NOT LOOPBACK"), "{quiet}");
        let tokened = fmu_warning(true, true, &any).unwrap();
        assert!(!tokened.contains("WARNING"), "{tokened}");
    }
}
