//! The calibration summary printed on the terminal.

use super::evidence::{self, BEST_TOLERANCE};
use calib_engine::calibration::Calibration;
use calib_engine::campaign::FreeParameter;
use calib_engine::optim::multistart::Stop;
use calib_engine::outcome::{CalibrationOutcome, Minimum, Named};
use std::fmt::Write;

/// Marks a value within 1% of its range from a bound, in the run table.
const AT_BOUND: char = '!';

/// Runs, best first, then the best point and the error before and after.
pub fn summary(c: &Calibration) -> String {
    summary_of(&c.outcome)
}

/// The summary of a calibration from its outcome: what `calib calibrate` prints, and `calib
/// submit` for a campaign a coordinator ran.
pub fn summary_of(result: &CalibrationOutcome) -> String {
    let mut s = String::new();
    let width = result
        .free_parameters
        .iter()
        .map(|p| p.name.len())
        .max()
        .unwrap_or(8)
        .max(12);
    write_runs(&mut s, result, width);
    write_best(&mut s, result, width);
    write_search(&mut s, result);
    s
}

/// The free parameters' values in `named`, NaN where one is missing.
fn point(free: &[FreeParameter], named: &Named<f64>) -> Vec<f64> {
    free.iter()
        .map(|p| named.get(&p.name).copied().unwrap_or(f64::NAN))
        .collect()
}

/// The table of runs, best first.
fn write_runs(s: &mut String, result: &CalibrationOutcome, width: usize) {
    let free = &result.free_parameters;
    let runs = &result.runs;
    let best_index = result.best_index();
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|&a, &b| runs[a].objective.total_cmp(&runs[b].objective));

    let _ = write!(s, "{:<24} {:>5} ", "method", "start");
    for p in free {
        let _ = write!(s, "{:>width$}  ", p.name.as_str());
    }
    let _ = writeln!(
        s,
        "{:>13} {:>6} {:>6} {:>6}   termination",
        "objective", "evals", "rounds", "iters"
    );
    for i in order {
        let r = &runs[i];
        let _ = write!(s, "{:<24} {:>5} ", r.method, r.start);
        for (p, v) in free.iter().zip(&point(free, &r.parameters)) {
            let mark = if evidence::at_bound(*v, p.nominal, p.min, p.max).is_some() {
                AT_BOUND
            } else {
                ' '
            };
            let _ = write!(s, "{:>width$.6e}{mark} ", v);
        }
        let mark = if i == best_index { "*" } else { " " };
        let restarts = match r.restarts {
            0 => String::new(),
            1 => " (after 1 restart off a plateau)".into(),
            n => format!(" (after {n} restarts off plateaus)"),
        };
        let _ = writeln!(
            s,
            "{:>13.6e} {:>6} {:>6} {:>6} {mark} {}{restarts}",
            r.objective, r.evaluations, r.rounds, r.iterations, r.termination
        );
    }
    let _ = writeln!(
        s,
        "(* best run; {AT_BOUND} on a bound: within {:.0}% of its range from it)",
        100.0 * evidence::BOUND_TOLERANCE
    );
}

/// The best point, its bounds, the objective and each compared series' error before and
/// after.
fn write_best(s: &mut String, result: &CalibrationOutcome, width: usize) {
    let free = &result.free_parameters;
    let best = &result.best;
    let best_point = point(free, &best.parameters);
    let best_objective = best.objective;
    let _ = writeln!(s);
    let _ = writeln!(s, "best ({} from start {}):", best.method, best.start);
    for (p, v) in free.iter().zip(&best_point) {
        let bound = match evidence::at_bound(*v, p.nominal, p.min, p.max) {
            Some(b) => format!("   at {} bound", b.word()),
            None => String::new(),
        };
        let _ = writeln!(
            s,
            "  {:<width$} = {:.6e}   (nominal {:.6e}){bound}",
            p.name, v, p.nominal
        );
    }
    for hit in evidence::bound_hits(free, &best_point) {
        let _ = writeln!(s, "  note: {}", evidence::bound_sentence(&hit));
    }
    let nominal = result.nominal_objective;
    let _ = writeln!(
        s,
        "objective {:.6e} -> {:.6e} ({:.1}x lower)",
        nominal,
        best_objective,
        nominal / best_objective
    );
    // One line per compared series: per output, and per experiment when there are several.
    let before = |named: &Named<f64>, output: &str| named.get(output).copied().unwrap_or(f64::NAN);
    let mut series: Vec<(String, f64, f64)> = Vec::new();
    if result.experiments.is_empty() {
        for (output, value) in best.rms.iter() {
            let was = before(&result.nominal_rms, output);
            series.push((output.to_string(), was, *value));
        }
    } else {
        for e in &result.experiments {
            for (output, value) in e.rms.iter() {
                let was = before(&e.nominal_rms, output);
                series.push((format!("{}: {output}", e.name), was, *value));
            }
        }
    }
    for (name, before, after) in series {
        let _ = writeln!(s, "  rms {name:<22} {before:.4e} -> {after:.4e}");
    }
}

/// How many runs reached the best, the distinct minima and what the search cost.
fn write_search(s: &mut String, result: &CalibrationOutcome) {
    let free = &result.free_parameters;
    let runs = &result.runs;
    let objectives: Vec<f64> = runs.iter().map(|r| r.objective).collect();
    let at_best = evidence::runs_at_best(&objectives);
    let _ = writeln!(
        s,
        "{} of {} runs reached the best objective within {:.0}%{}",
        at_best.count,
        at_best.of,
        100.0 * BEST_TOLERANCE,
        if at_best.count < 2 && at_best.of > 1 {
            " (only one: the best may not be the global minimum; add starts)"
        } else {
            ""
        }
    );
    let clusters = &result.clusters;
    let minima = clusters.iter().filter(|k| k.kind == Stop::Minimum).count();
    let stalls = stalls_note(clusters);

    let _ = writeln!(
        s,
        "{} distinct minima found by {} runs{stalls}; {} evaluations, {} rounds, {} \
         simulated, {} from cache, {:.2} s",
        minima,
        runs.len(),
        result.evaluations,
        result.rounds,
        result.simulated,
        result.from_store(),
        result.elapsed_seconds
    );
    write_minima(s, free, clusters);
}

/// The runs that stopped without a minimum, by why (`, 2 stalled on a plateau`), to append
/// to the line of minima; empty when every run found one.
fn stalls_note(clusters: &[Minimum]) -> String {
    let stalled = |of: Stop| {
        clusters
            .iter()
            .filter(|k| k.kind == of)
            .map(|k| k.runs.len())
            .sum::<usize>()
    };
    let mut stalls = String::new();
    for (of, words) in [
        (Stop::Plateau, "stalled on a plateau"),
        (Stop::Failures, "failed every simulation"),
    ] {
        let n = stalled(of);
        if n > 0 {
            let _ = write!(stalls, ", {n} {words}");
        }
    }
    stalls
}

/// The best [`SHOWN_MINIMA`] minima, each with its runs and the parameters its runs spread
/// over (a valley rather than a point).
fn write_minima(s: &mut String, free: &[FreeParameter], clusters: &[Minimum]) {
    for k in clusters
        .iter()
        .filter(|k| k.kind == Stop::Minimum)
        .take(SHOWN_MINIMA)
    {
        let loose: Vec<String> = free
            .iter()
            .filter_map(|p| {
                let (lo, hi) = k
                    .extent
                    .get(&p.name)
                    .copied()
                    .unwrap_or((f64::NAN, f64::NAN));
                (hi - lo > LOOSE * (p.max - p.min))
                    .then(|| format!("{} anywhere in [{lo:.4e}, {hi:.4e}]", p.name))
            })
            .collect();
        let runs = k.runs.len();
        let _ = writeln!(
            s,
            "  minimum {:.6e}: {} run{}{}",
            k.objective,
            runs,
            if runs == 1 { "" } else { "s" },
            if loose.is_empty() {
                String::new()
            } else {
                format!(", a valley: {}", loose.join(", "))
            }
        );
    }
}

/// Minima listed under the summary, best first.
const SHOWN_MINIMA: usize = 5;

/// A cluster whose runs spread over more than this share of a parameter's range at one
/// objective is a valley in that parameter.
const LOOSE: f64 = 0.01;
