//! `calib store`: look into, save and restore an evaluation store.

use super::{Failure, Outcome};
use calib_engine::store::{export, SledStore, Store, StoreError};
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Entries, size on disk, and evaluations served (hits) or simulated (misses).
    Stats {
        /// The store's folder.
        #[arg(long, value_name = "DIR")]
        db: PathBuf,
        /// Print the figures as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the whole store to standard output as versioned JSON lines.
    Export {
        #[arg(long, value_name = "DIR")]
        db: PathBuf,
    },
    /// Read an export from standard input into the store (created when absent).
    Import {
        #[arg(long, value_name = "DIR")]
        db: PathBuf,
    },
}

fn failure(e: StoreError) -> Failure {
    match e {
        StoreError::Import(_) => Failure::input(e.to_string()),
        _ => Failure::internal(e.to_string()),
    }
}

fn open(db: &std::path::Path, must_exist: bool) -> Result<SledStore, Failure> {
    if must_exist && !db.exists() {
        return Err(Failure::input(format!(
            "no store at {} (calib calibrate --db creates one)",
            db.display()
        )));
    }
    SledStore::open(db).map_err(failure)
}

pub fn run(args: Args) -> Outcome {
    match args.command {
        Command::Stats { db, json } => {
            let stats = open(&db, true)?.stats().map_err(failure)?;
            if json {
                println!("{}", serde_json::to_string(&stats).expect("plain data"));
            } else {
                println!("store        {}", db.display());
                println!("evaluations  {}", stats.evaluations);
                println!("campaigns    {}", stats.campaigns);
                println!("datasets     {}", stats.datasets);
                println!(
                    "size         {:.1} MiB",
                    stats.bytes as f64 / (1 << 20) as f64
                );
                println!("hits         {}", stats.hits);
                println!("misses       {}", stats.misses);
            }
        }
        Command::Export { db } => {
            let store = open(&db, true)?;
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            let counts = export::export(&store, &mut out).map_err(failure)?;
            out.flush()
                .map_err(|e| Failure::internal(format!("writing the export: {e}")))?;
            eprintln!(
                "exported {} evaluations, {} campaigns, {} datasets",
                counts.evaluations, counts.campaigns, counts.datasets
            );
        }
        Command::Import { db } => {
            let store = open(&db, false)?;
            let stdin = std::io::stdin();
            let counts = export::import(&store, &mut stdin.lock()).map_err(failure)?;
            eprintln!(
                "imported {} evaluations, {} campaigns, {} datasets",
                counts.evaluations, counts.campaigns, counts.datasets
            );
        }
    }
    Ok(())
}
