use super::{Failure, Outcome};
use calib_service::web::local::{self, UiConfig};
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Address to serve the web app on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: SocketAddr,
    /// Do not open a browser.
    #[arg(long)]
    no_open: bool,
    /// Evaluation store (a folder, created when absent), as for `calib calibrate --db`:
    /// campaigns and every simulated point are kept there; uploaded files and results in
    /// calib-api/ beside it [default: results/.calib-db].
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
    /// A host name (or NAME:PORT) the app also answers as, besides its address and
    /// localhost: requests naming any other Host, or sent by another web page, are refused.
    /// Repeatable.
    #[arg(long, value_name = "NAME", value_parser = calib_service::web::door::parse_allowed_host)]
    allow_host: Vec<String>,
}

pub fn run(args: Args) -> Outcome {
    let config = UiConfig {
        listen: args.listen,
        store: args
            .db
            .unwrap_or_else(|| PathBuf::from("results").join(".calib-db")),
        api: None,
        allow_hosts: args.allow_host,
    };
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let ui = local::start_ui(config).await?;
        let url = format!("http://{}/", ui.address());
        println!("calib ui at {url}");
        let _ = std::io::stdout().flush();
        if !args.no_open {
            open_browser(&url);
        }
        ui.wait().await?;
        Ok::<(), Failure>(())
    })
}

/// Open `url` in the desktop's browser; say so when there is none.
fn open_browser(url: &str) {
    let opener = if cfg!(target_os = "macos") {
        "open"
    } else {
        "xdg-open"
    };
    let opened = std::process::Command::new(opener)
        .arg(url)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn();
    if let Err(e) = opened {
        eprintln!("cannot open a browser ({opener}: {e}); open {url} yourself");
    }
}
