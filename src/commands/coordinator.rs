use super::{Failure, Outcome};
use calib_service::dispatch::{self, DispatchConfig};
use calib_service::server::{self, CoordinatorConfig};
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Address to serve on: the Calibration API, the Registry workers register with, health
    /// and reflection.
    #[arg(long, default_value = "0.0.0.0:50050")]
    listen: SocketAddr,
    #[command(flatten)]
    workers: super::WorkersArgs,
    #[command(flatten)]
    serve: super::security::ServeArgs,
    /// Evaluation store (a folder, as for `calib calibrate --db`). Campaigns it holds
    /// unfinished (their `calib calibrate` or coordinator was killed) are resumed on the
    /// workers as soon as the coordinator is up, replaying every stored evaluation instead of
    /// simulating it again.
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
    /// Folder for the results of resumed campaigns: result.json and the plots of each in
    /// DIR/<campaign name>/ [default: results/<campaign name>/ beside each campaign file,
    /// where `calib calibrate` puts them].
    #[arg(long, value_name = "DIR", requires = "db")]
    out: Option<PathBuf>,
    /// Folder of the Calibration API (`calib submit`, gRPC clients): uploaded datasets in
    /// DIR/datasets/, the results of submitted campaigns in DIR/results/<id>/ [default:
    /// calib-api/ beside the --db folder; without --db, a folder in the system's temporary
    /// directory].
    #[arg(long, value_name = "DIR")]
    api_dir: Option<PathBuf>,
    /// Also serve the web app (Model, Measurement, Calibration and Diagnosis tabs) on this
    /// address, over the same campaigns and workers: plain HTTP, answering only its own page
    /// (same origin) under its own address's name; with a token (--token-file), the page
    /// asks for it once and every API route requires it.
    #[arg(long, value_name = "ADDR")]
    http: Option<SocketAddr>,
    /// A host name (or NAME:PORT) the web app also answers as, besides its address and
    /// localhost: the name users or a reverse proxy reach it by. Repeatable.
    #[arg(long, value_name = "NAME", requires = "http", value_parser = calib_service::web::door::parse_allowed_host)]
    allow_host: Vec<String>,
}

pub fn run(args: Args) -> Outcome {
    let addresses = match &args.workers.workers {
        Some(list) => {
            dispatch::parse_list(list).map_err(|e| Failure::input(format!("--workers {e}")))?
        }
        None => Vec::new(),
    };
    let mut config = CoordinatorConfig::new(
        args.listen,
        args.workers.apply(DispatchConfig::new(addresses))?,
    );
    config.security = args.serve.server(&args.workers.dial)?;
    config.store = args.db;
    config.results = args.out;
    config.api = args.api_dir;
    config.http = args.http;
    config.http_allow_hosts = args.allow_host;
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let coordinator = server::start_coordinator(config).await?;
        println!("coordinator listening on {}", coordinator.address());
        if let Some(http) = coordinator.http_address() {
            println!("calib ui at http://{http}/");
        }
        coordinator.serve_until(super::terminated()).await?;
        Ok(())
    })
}
