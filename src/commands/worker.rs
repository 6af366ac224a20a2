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
        let worker = service::start_worker(config.clone())
            .await
            .map_err(|e| Failure::input(format!("--listen {}: {e}", config.listen)))?;
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
