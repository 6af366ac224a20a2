//! The calibration summary printed on the terminal.

use super::evidence::{self, BEST_TOLERANCE};
use crate::calibration::Calibration;
use crate::campaign::FreeParameter;
use crate::optim::multistart::Stop;
use serde_json::Value;
use std::fmt::Write;

/// Marks a value within 1% of its range from a bound, in the run table.
const AT_BOUND: char = '!';

/// Runs, best first, then the best point and the error before and after.
pub fn summary(c: &Calibration) -> String {
    summary_of(&super::result_json(c))
}

/// The summary of a calibration from its `result.json`: what `calib calibrate` prints, and
/// `calib submit` for a campaign a coordinator ran.
pub fn summary_of(result: &Value) -> String {
    let number = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let count = |v: &Value| v.as_u64().unwrap_or(0);
    let free: Vec<FreeParameter> = list(&result["free_parameters"])
        .iter()
        .map(|p| FreeParameter {
            name: p["name"].as_str().unwrap_or_default().to_string(),
            index: count(&p["index"]) as usize,
            nominal: number(&p["nominal"]),
            min: number(&p["min"]),
            max: number(&p["max"]),
            effect: p["effect"].as_bool().unwrap_or(false),
            scale: serde_json::from_value(p["scale"].clone()).unwrap_or_default(),
            experiment: p["experiment"].as_str().map(str::to_string),
        })
        .collect();
    let point =
        |named: &Value| -> Vec<f64> { free.iter().map(|p| number(&named[&p.name])).collect() };
    struct Run<'a> {
        method: &'a str,
        start: u64,
        point: Vec<f64>,
        objective: f64,
        evaluations: u64,
        rounds: u64,
        iterations: u64,
        termination: &'a str,
        restarts: u64,
    }
    let runs: Vec<Run> = list(&result["runs"])
        .iter()
        .map(|r| Run {
            method: r["method"].as_str().unwrap_or_default(),
            start: count(&r["start"]),
            point: point(&r["parameters"]),
            objective: number(&r["objective"]),
            evaluations: count(&r["evaluations"]),
            rounds: count(&r["rounds"]),
            iterations: count(&r["iterations"]),
            termination: r["termination"].as_str().unwrap_or_default(),
            restarts: count(&r["restarts"]),
        })
        .collect();
    let best = &result["best"];
    let best_index = runs
        .iter()
        .position(|r| Some(r.method) == best["method"].as_str() && r.start == count(&best["start"]))
        .unwrap_or(0);

    let mut s = String::new();
    let names: Vec<&str> = free.iter().map(|p| p.name.as_str()).collect();
    let width = names.iter().map(|n| n.len()).max().unwrap_or(8).max(12);
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|&a, &b| runs[a].objective.total_cmp(&runs[b].objective));

    let _ = write!(s, "{:<24} {:>5} ", "method", "start");
    for n in &names {
        let _ = write!(s, "{n:>width$}  ");
    }
    let _ = writeln!(
        s,
        "{:>13} {:>6} {:>6} {:>6}   termination",
        "objective", "evals", "rounds", "iters"
    );
    for i in order {
        let r = &runs[i];
        let _ = write!(s, "{:<24} {:>5} ", r.method, r.start);
        for (p, v) in free.iter().zip(&r.point) {
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
    let best_point = point(&best["parameters"]);
    let best_objective = number(&best["objective"]);
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "best ({} from start {}):",
        best["method"].as_str().unwrap_or_default(),
        count(&best["start"])
    );
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
    for hit in evidence::bound_hits(&free, &best_point) {
        let _ = writeln!(s, "  note: {}", evidence::bound_sentence(&hit));
    }
    let nominal = number(&result["nominal_objective"]);
    let _ = writeln!(
        s,
        "objective {:.6e} -> {:.6e} ({:.1}x lower)",
        nominal,
        best_objective,
        nominal / best_objective
    );
    // One line per compared series: per output, and per experiment when there are several.
    let experiments = list(&result["experiments"]);
    let mut series: Vec<(String, f64, f64)> = Vec::new();
    if experiments.is_empty() {
        if let Some(after) = best["rms"].as_object() {
            for (output, value) in after {
                let before = number(&result["nominal_rms"][output]);
                series.push((output.clone(), before, number(value)));
            }
        }
    } else {
        for e in experiments {
            let name = e["name"].as_str().unwrap_or_default();
            if let Some(after) = e["rms"].as_object() {
                for (output, value) in after {
                    let before = number(&e["nominal_rms"][output]);
                    series.push((format!("{name}: {output}"), before, number(value)));
                }
            }
        }
    }
    for (name, before, after) in series {
        let _ = writeln!(s, "  rms {name:<22} {before:.4e} -> {after:.4e}");
    }
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
    let clusters = list(&result["clusters"]);
    let kind = |k: &Value, of: Stop| serde_json::to_value(of).ok().as_ref() == Some(&k["kind"]);
    let minima = clusters.iter().filter(|k| kind(k, Stop::Minimum)).count();
    let stalled = |of: Stop| {
        clusters
            .iter()
            .filter(|k| kind(k, of))
            .map(|k| list(&k["runs"]).len())
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
    let counted = super::runs::counts(result);
    let _ = writeln!(
        s,
        "{} distinct minima found by {} runs{stalls}; {} evaluations, {} rounds, {} \
         simulated, {} from cache, {:.2} s",
        minima,
        runs.len(),
        counted.evaluations,
        count(&result["rounds"]),
        counted.simulated,
        counted.from_store,
        number(&result["elapsed_seconds"])
    );
    for k in clusters
        .iter()
        .filter(|k| kind(k, Stop::Minimum))
        .take(SHOWN_MINIMA)
    {
        let loose: Vec<String> = free
            .iter()
            .filter_map(|p| {
                let extent = &k["extent"][&p.name];
                let (lo, hi) = (number(&extent[0]), number(&extent[1]));
                (hi - lo > LOOSE * (p.max - p.min))
                    .then(|| format!("{} anywhere in [{lo:.4e}, {hi:.4e}]", p.name))
            })
            .collect();
        let runs = list(&k["runs"]).len();
        let _ = writeln!(
            s,
            "  minimum {:.6e}: {} run{}{}",
            number(&k["objective"]),
            runs,
            if runs == 1 { "" } else { "s" },
            if loose.is_empty() {
                String::new()
            } else {
                format!(", a valley: {}", loose.join(", "))
            }
        );
    }
    s
}

/// The elements of a JSON array (none for anything else).
fn list(v: &Value) -> &[Value] {
    v.as_array().map_or(&[], Vec::as_slice)
}

/// Minima listed under the summary, best first.
const SHOWN_MINIMA: usize = 5;

/// A cluster whose runs spread over more than this share of a parameter's range at one
/// objective is a valley in that parameter.
const LOOSE: f64 = 0.01;
