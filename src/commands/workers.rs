//! The options of the commands that dispatch to workers, connecting to them, and telling
//! the user what is awaited while no worker is up.

use super::Failure;
use calib_service::dispatch::{self, DispatchConfig, Health, RemoteWorkers, WorkerPool};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Where evaluations run, for the commands that dispatch them.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkersArgs {
    /// Workers to spread evaluations over, comma separated: http://HOST:PORT or
    /// https://HOST:PORT (one worker) or dns:///NAME:PORT (every address NAME resolves to,
    /// re-resolved periodically; over TLS verified as NAME when --tls-ca is given).
    #[arg(long, value_name = "LIST")]
    pub workers: Option<String>,
    #[command(flatten)]
    pub dial: super::security::DialArgs,
    /// Deadline of one request to a worker [s].
    #[arg(long, default_value = "120", value_name = "SECONDS", value_parser = seconds)]
    pub deadline: Duration,
    /// How long to wait for a worker to be up before evaluations fail [s].
    #[arg(long, default_value = "300", value_name = "SECONDS", value_parser = seconds)]
    pub wait_for_workers: Duration,
}

/// A span of seconds: a positive finite number (`inf`, `nan`, `0` and negatives refused).
fn seconds(text: &str) -> Result<Duration, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number of seconds"))?;
    if !value.is_finite() || value <= 0.0 {
        return Err(format!(
            "`{text}`: give a finite number of seconds above 0 (there is no unbounded wait)"
        ));
    }
    Duration::try_from_secs_f64(value).map_err(|e| format!("`{text}`: {e}"))
}

impl WorkersArgs {
    /// Connect to the workers of `list` and wait for one to be up (`--wait-for-workers`),
    /// telling `status` what is awaited as it changes.
    pub fn connect_reporting(
        &self,
        list: &str,
        status: &dyn Fn(&str),
    ) -> Result<RemoteWorkers, Failure> {
        let addresses =
            dispatch::parse_list(list).map_err(|e| Failure::input(format!("--workers {e}")))?;
        let config = self.apply(DispatchConfig::new(addresses))?;
        let wait = config.wait_for_workers;
        let workers = RemoteWorkers::connect(config)?;
        workers
            .wait_for_worker(wait, status)
            .map_err(Failure::internal)?;
        Ok(workers)
    }

    /// [`Self::connect_reporting`] with every change on standard error.
    pub fn connect(&self, list: &str) -> Result<RemoteWorkers, Failure> {
        self.connect_reporting(list, &|line| eprintln!("{line}"))
    }

    pub fn apply(&self, mut config: DispatchConfig) -> Result<DispatchConfig, Failure> {
        config.deadline = self.deadline;
        config.wait_for_workers = self.wait_for_workers;
        config.security = self.dial.client()?;
        Ok(config)
    }
}

/// Run `work` while a thread [`watch`]es the pool of `workers`, telling `status`.
pub fn while_watching<T>(
    workers: &RemoteWorkers,
    status: &(dyn Fn(&str) + Sync),
    work: impl FnOnce() -> T,
) -> T {
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        scope.spawn(|| watch(workers.pool(), &stop, status));
        let result = work();
        stop.store(true, Ordering::SeqCst);
        result
    })
}

/// A status line of [`watch`] on standard error, `workers: ` before it (the empty line
/// that says a worker is back is left out).
pub fn print_status(line: &str) {
    if !line.is_empty() {
        eprintln!("workers: {line}");
    }
}

/// Watch `pool` until `stop` is set: whenever no worker is up, `status` hears what is
/// awaited (each change once), and an empty line once a worker is back.
pub fn watch(pool: &WorkerPool, stop: &AtomicBool, status: &dyn Fn(&str)) {
    let wait = pool.config().wait_for_workers;
    let mut last = String::new();
    while !stop.load(Ordering::SeqCst) {
        let workers = pool.workers();
        let state = if workers.iter().any(|w| w.health == Health::Up) {
            String::new()
        } else {
            format!(
                "no worker up, waiting up to {:.0} s: {}",
                wait.as_secs_f64(),
                dispatch::describe(&workers)
            )
        };
        if state != last {
            status(&state);
            last = state;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[cfg(test)]
mod tests {
    use super::seconds;
    use std::time::Duration;

    #[test]
    fn seconds_are_finite_and_positive() {
        assert_eq!(seconds("2.5"), Ok(Duration::from_millis(2500)));
        for bad in ["inf", "-1", "0", "nan", "soon", "1e300"] {
            assert!(seconds(bad).is_err(), "{bad}");
        }
    }
}
