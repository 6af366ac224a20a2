//! `calib bench diagnose --random N --seed S`: the diagnosis on records drawn at random (see
//! [`calib_analysis::diagnosis::benchmark`]): a confusion matrix of the effect each record
//! holds against what was selected, the false-positive rate on clean records, the rate at
//! which both effects of two-effect records are named, discovery's right multiple on
//! cogging records, the final objective over the noise floor and the cost.

use super::{Failure, Outcome};
use calib_analysis::diagnosis::benchmark::{draw, Category, Draw, KINDS};
use calib_analysis::diagnosis::outside::found_outside_the_library;
use calib_analysis::diagnosis::{diagnose, NOISE_FACTOR};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// What to run: records `from..from + count` of `seed` (record i has category i mod 10:
/// 2 clean, 5 one effect, 2 two effects, 1 cogging in every 10), `jobs` at a time, the
/// simulator scripts in `repo`'s tests/python/.
pub struct RandomArgs {
    pub count: usize,
    pub seed: u64,
    pub from: usize,
    /// Only records of these categories (clean, single, double, cogging); empty: all.
    pub only: Vec<String>,
    /// Only print the draws.
    pub list: bool,
    pub jobs: usize,
    pub json: Option<PathBuf>,
    /// Where to keep the records and their campaigns (else a temporary folder, removed).
    pub keep: Option<PathBuf>,
    pub repo: PathBuf,
}

/// What one record's diagnosis gave.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    pub index: usize,
    pub category: &'static str,
    pub holds: String,
    pub expected: Vec<String>,
    pub selected: Vec<String>,
    /// Sets the diagnosis named as equivalents of its selection (each sorted).
    pub equivalents: Vec<Vec<String>>,
    /// Not passed, but the record's effects are one of those equivalents, within the factor.
    pub among_equivalents: bool,
    /// For a cogging record: the multiples of `armJoint.phi` discovery proposed on the arm.
    pub multiples: Vec<usize>,
    pub ratio: f64,
    pub simulations: u64,
    pub seconds: f64,
    pub settings: String,
    pub pass: bool,
    pub error: Option<String>,
}

/// Longest a record's simulation may take: the independent simulator resolves each stick and
/// slip of a Coulomb friction as an event, and a friction that barely holds can make it
/// chatter for ever.
const SIMULATOR_DEADLINE: Duration = Duration::from_secs(300);

fn make_record(d: &Draw, repo: &Path, csv: &Path) -> Result<(), String> {
    let script = repo.join(d.script());
    let mut child = std::process::Command::new("python3")
        .arg(&script)
        .arg("--out")
        .arg(csv)
        .args(d.simulator_args())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| format!("python3 cannot run {}: {e}", script.display()))?;
    let started = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if started.elapsed() < SIMULATOR_DEADLINE => {
                std::thread::sleep(Duration::from_millis(100))
            }
            Ok(None) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "{} did not finish in {} s (its events chatter)",
                    script.display(),
                    SIMULATOR_DEADLINE.as_secs()
                ));
            }
            Err(e) => return Err(format!("{}: {e}", script.display())),
        }
    };
    if !status.success() {
        let mut stderr = String::new();
        if let Some(mut pipe) = child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut pipe, &mut stderr);
        }
        return Err(format!("{} failed: {stderr}", script.display()));
    }
    Ok(())
}

/// The multiples `k` of the terms `sin(k·armJoint.phi …)` discovery proposed on the arm.
fn arm_multiples(found: &calib_analysis::diagnosis::outside::Found) -> Vec<usize> {
    let mut ks: Vec<usize> = found
        .proposals()
        .iter()
        .filter(|(p, _)| p.place == "armJoint")
        .flat_map(|(p, _)| p.harmonics.iter())
        .filter(|h| h.angle == "armJoint.phi")
        .map(|h| h.multiple)
        .collect();
    ks.sort_unstable();
    ks.dedup();
    ks
}

fn run_record(d: &Draw, repo: &Path, dir: &Path, keep: bool) -> Record {
    let started = Instant::now();
    let mut record = Record {
        index: d.index,
        category: d.category.name(),
        holds: d.describe(),
        expected: d.expected(),
        selected: Vec::new(),
        equivalents: Vec::new(),
        among_equivalents: false,
        multiples: Vec::new(),
        ratio: f64::NAN,
        simulations: 0,
        seconds: 0.0,
        settings: format!("{} {} ×{}", d.bounds, d.methods, d.starts),
        pass: false,
        error: None,
    };
    let csv = dir.join(format!("record{}.csv", d.index));
    let outcome = (|| -> Result<(), String> {
        make_record(d, repo, &csv)?;
        let text = d.campaign(&csv);
        let toml = dir.join(format!("record{}.toml", d.index));
        if keep {
            std::fs::write(&toml, &text).map_err(|e| format!("{}: {e}", toml.display()))?;
        }
        let campaign = Campaign::parse(&text, &toml).map_err(|e| e.to_string())?;
        let diagnosis = diagnose(&campaign, &LocalEvaluator, &Silent).map_err(|e| e.to_string())?;
        record.selected = diagnosis.selected.clone();
        record.selected.sort();
        record.simulations = diagnosis.stats.evaluations.simulated + diagnosis.stats.trajectories;
        let mut ratio = diagnosis.final_fit.objective / diagnosis.noise_floor;
        if let Some((k, _)) = d.cogging {
            let found = found_outside_the_library(&diagnosis, &LocalEvaluator, &Silent)
                .map_err(|e| e.to_string())?;
            record.multiples = arm_multiples(&found);
            if let Some(refit) = found
                .refits
                .iter()
                .map(|r| r.ratio_after())
                .reduce(f64::min)
            {
                ratio = ratio.min(refit);
            }
            record.pass = record.multiples.contains(&(k as usize)) && ratio <= NOISE_FACTOR;
        } else {
            record.pass = record.selected == record.expected && ratio <= NOISE_FACTOR;
            record.equivalents = diagnosis.equivalent_sets();
            record.among_equivalents = !record.pass
                && ratio <= NOISE_FACTOR
                && record.equivalents.contains(&record.expected);
        }
        record.ratio = ratio;
        Ok(())
    })();
    if !keep {
        let _ = std::fs::remove_file(&csv);
    }
    if let Err(e) = outcome {
        record.error = Some(e);
    }
    record.seconds = started.elapsed().as_secs_f64();
    record
}

pub fn run(args: RandomArgs) -> Outcome {
    if args.list {
        for d in (args.from..args.from + args.count).map(|i| draw(args.seed, i)) {
            if args.only.is_empty() || args.only.iter().any(|c| c == category_key(d.category)) {
                println!(
                    "{:>4} {:<20} {:<52} {} {} ×{}",
                    d.index,
                    d.category.name(),
                    d.describe(),
                    d.bounds,
                    d.methods,
                    d.starts
                );
            }
        }
        return Ok(());
    }
    // Absolute: each campaign names its record by this path.
    let dir = match &args.keep {
        Some(keep) => std::path::absolute(keep)
            .map_err(|e| Failure::input(format!("{}: {e}", keep.display())))?,
        None => std::env::temp_dir().join(format!("calib-random-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).map_err(|e| Failure::input(format!("{}: {e}", dir.display())))?;
    let draws: Vec<Draw> = (args.from..args.from + args.count)
        .map(|i| draw(args.seed, i))
        .filter(|d| args.only.is_empty() || args.only.iter().any(|c| c == category_key(d.category)))
        .collect();
    let next = Mutex::new(0usize);
    let records: Mutex<Vec<Option<Record>>> = Mutex::new(vec![None; draws.len()]);
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.max(1) {
            scope.spawn(|| loop {
                let i = {
                    let mut n = next.lock().unwrap();
                    *n += 1;
                    *n - 1
                };
                let Some(d) = draws.get(i) else { break };
                let r = run_record(d, &args.repo, &dir, args.keep.is_some());
                eprintln!(
                    "{:>4} {:<20} {:<52} {:<26} -> {:<56} {:>8.3}x {:>7} sims {:>6.1} s {}",
                    r.index,
                    r.category,
                    r.holds,
                    r.settings,
                    match &r.error {
                        Some(e) => format!("error: {e}"),
                        None if d.cogging.is_some() => format!("k {:?}", r.multiples),
                        None if r.selected.is_empty() => "nothing".into(),
                        None => r.selected.join(" + "),
                    },
                    r.ratio,
                    r.simulations,
                    r.seconds,
                    verdict_label(&r)
                );
                records.lock().unwrap()[i] = Some(r);
            });
        }
    });
    if args.keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let records: Vec<Record> = records
        .into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every record ran"))
        .collect();
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&records).expect("plain data");
        std::fs::write(path, text)
            .map_err(|e| Failure::input(format!("{}: {e}", path.display())))?;
    }
    print_tables(&draws, &records, args.seed);
    Ok(())
}

/// The name `--only` gives a category.
fn category_key(c: Category) -> &'static str {
    match c {
        Category::Clean => "clean",
        Category::Single => "single",
        Category::Double => "double",
        Category::Cogging => "cogging",
    }
}

fn percent(n: usize, of: usize) -> String {
    if of == 0 {
        "–".into()
    } else {
        format!("{n} of {of} ({:.1}%)", 100.0 * n as f64 / of as f64)
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// The summary per category, the confusion matrix of one-effect records and the cost.
/// How a record's outcome is marked in the progress lines.
fn verdict_label(r: &Record) -> &'static str {
    match (r.pass, r.among_equivalents) {
        (true, _) => "ok",
        (false, true) => "MISS (named among equivalents)",
        (false, false) => "MISS",
    }
}

fn print_tables(draws: &[Draw], records: &[Record], seed: u64) {
    print_categories(draws, records, seed);
    print_confusion(draws, records);
    let total_seconds: f64 = records.iter().map(|r| r.seconds).sum();
    println!("\n{:.0} s of diagnosis in all", total_seconds);
}

/// Per category: the share passed, the final objective over the floor and the cost; then the
/// clean records' false-positive rate.
fn print_categories(draws: &[Draw], records: &[Record], seed: u64) {
    println!("seed {seed}, {} records\n", records.len());
    println!("| records | pass | final / floor: median, 90%, most | simulations: median, most |");
    println!("|---|---|---|---|");
    for category in [
        Category::Clean,
        Category::Single,
        Category::Double,
        Category::Cogging,
    ] {
        let of: Vec<&Record> = draws
            .iter()
            .zip(records)
            .filter(|(d, _)| d.category == category)
            .map(|(_, r)| r)
            .collect();
        let mut ratios: Vec<f64> = of
            .iter()
            .map(|r| r.ratio)
            .filter(|r| r.is_finite())
            .collect();
        ratios.sort_by(f64::total_cmp);
        let mut sims: Vec<f64> = of.iter().map(|r| r.simulations as f64).collect();
        sims.sort_by(f64::total_cmp);
        if of.is_empty() {
            // A category the run did not draw (--kinds): a row of dashes, not NaN.
            println!("| {} | – | – | – |", category.name());
            continue;
        }
        println!(
            "| {} | {} | {:.3}, {:.3}, {:.3} | {:.0}, {:.0} |",
            category.name(),
            percent(of.iter().filter(|r| r.pass).count(), of.len()),
            quantile(&ratios, 0.5),
            quantile(&ratios, 0.9),
            quantile(&ratios, 1.0),
            quantile(&sims, 0.5),
            quantile(&sims, 1.0),
        );
    }
    let among = records.iter().filter(|r| r.among_equivalents).count();
    println!(
        "\nmissed, but the record's effects named among the sets the diagnosis says the record \
         cannot tell from its selection: {among}"
    );
    let clean: Vec<&Record> = draws
        .iter()
        .zip(records)
        .filter(|(d, _)| d.category == Category::Clean)
        .map(|(_, r)| r)
        .collect();
    println!(
        "\nclean records given an effect: {}",
        percent(
            clean.iter().filter(|r| !r.selected.is_empty()).count(),
            clean.len()
        )
    );
}

/// One-effect records: per effect held, how often it alone was selected, and what else was.
fn print_confusion(draws: &[Draw], records: &[Record]) {
    println!("\none effect: what was selected, per effect the record holds\n");
    println!("| holds | right | what else was selected |");
    println!("|---|---|---|");
    for kind in KINDS.iter() {
        let of: Vec<&Record> = draws
            .iter()
            .zip(records)
            .filter(|(d, _)| {
                d.category == Category::Single && KINDS[d.effects[0].0].name == kind.name
            })
            .map(|(_, r)| r)
            .collect();
        let right = of.iter().filter(|r| r.pass).count();
        let mut others: Vec<String> = of
            .iter()
            .filter(|r| !r.pass)
            .map(|r| match &r.error {
                Some(_) => "error".into(),
                None if r.selected.is_empty() => format!("nothing ({:.2}x)", r.ratio),
                None => format!("{} ({:.2}x)", r.selected.join(" + "), r.ratio),
            })
            .collect();
        others.sort();
        println!(
            "| {} | {} | {} |",
            kind.effect,
            percent(right, of.len()),
            others.join("; ")
        );
    }
}
