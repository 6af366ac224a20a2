use super::{Failure, Outcome};
use calib_coordinator::dispatch::{self, DispatchConfig};
use calib_coordinator::server::{self, CoordinatorConfig};
use std::net::SocketAddr;

#[derive(clap::Args)]
pub struct Args {
    /// Address to serve on: health, reflection and the Registry workers register with.
    #[arg(long, default_value = "0.0.0.0:50050")]
    listen: SocketAddr,
    #[command(flatten)]
    workers: super::WorkersArgs,
}

pub fn run(args: Args) -> Outcome {
    let addresses = match &args.workers.workers {
        Some(list) => {
            dispatch::parse_list(list).map_err(|e| Failure::input(format!("--workers {e}")))?
        }
        None => Vec::new(),
    };
    let config = CoordinatorConfig {
        listen: args.listen,
        dispatch: args.workers.apply(DispatchConfig::new(addresses)),
    };
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let coordinator = server::start_coordinator(config).await?;
        println!("coordinator listening on {}", coordinator.address());
        coordinator.wait().await?;
        Ok(())
    })
}
