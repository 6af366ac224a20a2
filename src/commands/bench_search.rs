//! `calib bench search`: how many rounds, evaluations and how much wall time each search
//! method takes to reach a campaign's optimum, alone and in the campaign's own mix.
//!
//! Every configuration is calibrated once on this machine; each run's batches (their sizes,
//! and the run's best objective after each) are recorded through the progress hooks. The
//! wall time on `N` workers is then replayed on a virtual clock: every simulation costs the
//! same fixed time on one of `N` slots, a run sends its next batch when its last one is
//! back, runs go concurrently as the multistart runs them (64 at a time, in plan order), and
//! a batch's points take the earliest free slots in the order the batches were sent. The
//! clock counts every evaluation, including those the evaluation cache answered.

use super::{Failure, Outcome};
use calib_engine::calibration::{self, Calibration};
use calib_engine::campaign::{Campaign, Method};
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::multistart::MAX_CONCURRENT_RUNS;
use calib_engine::optim::problem::Progress;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::PathBuf;
use std::sync::Mutex;

#[derive(clap::Args)]
pub struct Args {
    /// Campaigns to search (each with every method alone, then its own methods together).
    #[arg(long, num_args = 1.., default_values = ["examples/furuta.toml", "examples/hx.toml"])]
    campaigns: Vec<PathBuf>,
    /// Simulated workers (slots) the wall time is given for.
    #[arg(long, num_args = 1.., default_values_t = [1usize, 8, 64, 512])]
    workers: Vec<usize>,
    /// Cost of one simulation on one slot, in milliseconds, on the virtual clock.
    #[arg(long, default_value_t = 2.0)]
    cost_ms: f64,
    /// Also measure CMA-ES with this smallest population (`cma_population`), e.g. as many
    /// points per round as differential evolution's population.
    #[arg(long)]
    cma_population: Option<usize>,
    /// Also measure this mix of methods, comma-separated (e.g. a campaign's former default,
    /// `--mix nelder-mead,powell,differential-evolution`); may be given more than once.
    #[arg(long = "mix", value_name = "METHODS", value_parser = parse_mix)]
    mixes: Vec<Vec<Method>>,
    /// Leave out the rows of each method alone: the campaign's own mix and `--mix` only.
    #[arg(long)]
    mixes_only: bool,
    /// Print the table on standard error and the rows as JSON on standard output.
    #[arg(long)]
    json: bool,
}

/// `a,b,c` as methods, naming the valid ones when a name is not.
fn parse_mix(text: &str) -> Result<Vec<Method>, String> {
    text.split(',')
        .map(|name| {
            let name = name.trim();
            Method::ALL
                .into_iter()
                .find(|m| m.name() == name)
                .ok_or_else(|| {
                    let valid: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
                    format!("unknown method `{name}`: one of {}", valid.join(", "))
                })
        })
        .collect()
}

fn mix_label(methods: &[Method]) -> String {
    let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
    format!("mix ({})", names.join(", "))
}

/// Each run's batches in the order it sent them: (points, the run's best objective after).
#[derive(Default)]
struct Batches {
    before: Mutex<Vec<usize>>,
    runs: Mutex<Vec<Vec<(usize, f64)>>>,
}

impl Progress for Batches {
    fn evaluated(&self, count: usize, _best_objective: f64) {
        self.before.lock().expect("batches lock").push(count);
    }

    fn planned(&self, runs: &[(String, usize)]) {
        *self.runs.lock().expect("batches lock") = vec![Vec::new(); runs.len()];
    }

    fn run_round(&self, run: usize) {
        self.runs.lock().expect("batches lock")[run].push((0, f64::INFINITY));
    }

    fn run_evaluated(&self, run: usize, count: usize, run_best_objective: f64) {
        let mut runs = self.runs.lock().expect("batches lock");
        let batches = &mut runs[run];
        if batches.is_empty() {
            batches.push((0, f64::INFINITY));
        }
        let last = batches.last_mut().expect("a batch");
        last.0 += count;
        last.1 = run_best_objective;
    }
}

/// One configuration's calibration and its batches.
struct Measured {
    label: String,
    calibration: Calibration,
    before: Vec<usize>,
    runs: Vec<Vec<(usize, f64)>>,
}

pub fn run(args: Args) -> Outcome {
    let mut rows = Vec::new();
    for path in &args.campaigns {
        let campaign = Campaign::load(path).map_err(|e| Failure::input(e.to_string()))?;
        let mut configurations: Vec<(String, Vec<Method>, Option<usize>)> = if args.mixes_only {
            Vec::new()
        } else {
            Method::ALL
                .iter()
                .map(|m| (m.name().to_string(), vec![*m], None))
                .collect()
        };
        if let (Some(population), false) = (args.cma_population, args.mixes_only) {
            configurations.push((
                format!("cma-es, population {population}"),
                vec![Method::CmaEs],
                Some(population),
            ));
        }
        for mix in &args.mixes {
            configurations.push((mix_label(mix), mix.clone(), None));
        }
        let own = campaign.search.methods.clone();
        configurations.push((format!("{} (the campaign's)", mix_label(&own)), own, None));
        let mut measured = Vec::new();
        for (label, methods, population) in configurations {
            let mut c = campaign.clone();
            c.search.methods = methods;
            c.search.cma_population = population.or(c.search.cma_population);
            let batches = Batches::default();
            let calibration = calibration::calibrate(&c, LocalEvaluator, &batches)?;
            measured.push(Measured {
                label,
                calibration,
                before: batches.before.into_inner().expect("batches lock"),
                runs: batches.runs.into_inner().expect("batches lock"),
            });
        }
        rows.extend(print_table(&campaign, &measured, &args));
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::Value::Array(rows)).expect("plain data")
        );
    }
    Ok(())
}

/// Print the campaign's table (on standard error under `--json`) and return its rows as JSON.
fn print_table(campaign: &Campaign, measured: &[Measured], args: &Args) -> Vec<serde_json::Value> {
    let say = |line: &str| {
        if args.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    let mut rows = Vec::new();
    let best = measured
        .iter()
        .map(|m| m.calibration.best_run().objective)
        .fold(f64::INFINITY, f64::min);
    let threshold = best + 0.01 * best.abs();
    say(&format!(
        "{}: {} starts, {} evaluations per run; best objective {best:.6e}; within 1%: <= {threshold:.6e}",
        campaign.name, campaign.search.starts, campaign.search.max_evaluations
    ));
    let width = measured
        .iter()
        .map(|m| m.label.len())
        .max()
        .unwrap_or(0)
        .max(44);
    let mut head = format!(
        "  {:<width$} {:>16} {:>7} {:>7} {:>9} {:>7}",
        "methods", "best", "rounds", "to 1%", "evals", "at 1%"
    );
    for n in &args.workers {
        head.push_str(&format!(" {:>10}", format!("{n} w [s]")));
    }
    say(&head);
    for m in measured {
        let c = &m.calibration;
        let at_best = c.runs.iter().filter(|r| r.objective <= threshold).count();
        let to_best = rounds_to(m, threshold).map_or("-".to_string(), |r| r.to_string());
        let mut line = format!(
            "  {:<width$} {:>16.10e} {:>7} {:>7} {:>9} {:>7}",
            m.label,
            c.best_run().objective,
            c.rounds(),
            to_best,
            c.evaluations(),
            format!("{at_best}/{}", c.runs.len())
        );
        let mut walls = serde_json::Map::new();
        for &n in &args.workers {
            let wall = wall_time(m, n, args.cost_ms / 1e3);
            line.push_str(&format!(" {wall:>10.3}"));
            walls.insert(n.to_string(), serde_json::json!(wall));
        }
        say(&line);
        rows.push(serde_json::json!({
            "campaign": campaign.name,
            "label": m.label,
            "best_objective": c.best_run().objective,
            "rounds": c.rounds(),
            "rounds_to_1_percent": rounds_to(m, threshold),
            "evaluations": c.evaluations(),
            "runs_within_1_percent": at_best,
            "runs": c.runs.len(),
            "wall_seconds": walls,
        }));
    }
    say(&format!(
        "  (rounds: batches waited for one after another; to 1%: rounds until a run first \
         came within 1% of the best; at 1%: runs ending there; N w: wall time on N workers, \
         {} ms per simulation)",
        args.cost_ms
    ));
    rows
}

/// Rounds until the first run came within `threshold`: the rounds before the runs (nominal
/// point, screening), then the fewest rounds any run of the first concurrent group took.
fn rounds_to(m: &Measured, threshold: f64) -> Option<usize> {
    let mut offset = m.before.len();
    for group in m.runs.chunks(MAX_CONCURRENT_RUNS) {
        let first = group
            .iter()
            .filter_map(|batches| batches.iter().position(|(_, best)| *best <= threshold))
            .min();
        if let Some(r) = first {
            return Some(offset + r + 1);
        }
        offset += group.iter().map(Vec::len).max().unwrap_or(0);
    }
    None
}

/// The campaign's wall time on `slots` workers at `cost` seconds per simulation (see the
/// module documentation).
fn wall_time(m: &Measured, slots: usize, cost: f64) -> f64 {
    let slots = slots.max(1);
    let mut clock: f64 = m
        .before
        .iter()
        .map(|&k| k.div_ceil(slots) as f64 * cost)
        .sum();
    for group in m.runs.chunks(MAX_CONCURRENT_RUNS) {
        clock = replay(group, slots, cost, clock);
    }
    clock
}

/// Replay concurrent runs' batches from `start` on `slots` slots; when the last ends.
fn replay(runs: &[Vec<(usize, f64)>], slots: usize, cost: f64, start: f64) -> f64 {
    // Slots by when they are free (as integer nanoseconds, so the heap orders them).
    let nanos = |t: f64| (t * 1e9).round() as u64;
    let mut free: BinaryHeap<Reverse<u64>> = (0..slots).map(|_| Reverse(nanos(start))).collect();
    // Batches waiting to be sent: (when, run, batch index).
    let mut sends: BinaryHeap<Reverse<(u64, usize, usize)>> = runs
        .iter()
        .enumerate()
        .filter(|(_, b)| !b.is_empty())
        .map(|(r, _)| Reverse((nanos(start), r, 0)))
        .collect();
    let mut end = nanos(start);
    let step = nanos(cost);
    while let Some(Reverse((at, run, index))) = sends.pop() {
        let mut done = at;
        for _ in 0..runs[run][index].0 {
            let Reverse(slot) = free.pop().expect("a slot");
            let finish = slot.max(at) + step;
            free.push(Reverse(finish));
            done = done.max(finish);
        }
        end = end.max(done);
        if index + 1 < runs[run].len() {
            sends.push(Reverse((done, run, index + 1)));
        }
    }
    end as f64 / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concurrent_batches_share_the_slots() {
        // Two runs, each two batches of 4 points, 1 s per simulation.
        let runs = vec![vec![(4, 1.0), (4, 0.5)], vec![(4, 2.0), (4, 1.0)]];
        // 8 slots: both runs' batches run side by side: 2 s.
        assert_eq!(replay(&runs, 8, 1.0, 0.0), 2.0);
        // 4 slots: the runs take turns: 4 s.
        assert_eq!(replay(&runs, 4, 1.0, 0.0), 4.0);
        // 1 slot: 16 simulations one after another.
        assert_eq!(replay(&runs, 1, 1.0, 10.0), 26.0);
    }
}
