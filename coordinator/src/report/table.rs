//! The calibration summary printed on the terminal.

use super::evidence::{self, BEST_TOLERANCE};
use crate::calibration::Calibration;
use crate::optim::multistart::Stop;
use std::fmt::Write;

/// Marks a value within 1% of its range from a bound, in the run table.
const AT_BOUND: char = '!';

/// Runs, best first, then the best point and the error before and after.
pub fn summary(c: &Calibration) -> String {
    let mut s = String::new();
    let names: Vec<&str> = c.campaign.free.iter().map(|p| p.name.as_str()).collect();
    let width = names.iter().map(|n| n.len()).max().unwrap_or(8).max(12);
    let mut order: Vec<usize> = (0..c.runs.len()).collect();
    order.sort_by(|&a, &b| c.runs[a].objective.total_cmp(&c.runs[b].objective));

    let _ = write!(s, "{:<24} {:>5} ", "method", "start");
    for n in &names {
        let _ = write!(s, "{n:>width$}  ");
    }
    let _ = writeln!(
        s,
        "{:>13} {:>6} {:>6}   termination",
        "objective", "evals", "iters"
    );
    for i in order {
        let r = &c.runs[i];
        let _ = write!(s, "{:<24} {:>5} ", r.method.name(), r.start);
        for (p, v) in c.campaign.free.iter().zip(&r.point) {
            let mark = if evidence::at_bound(*v, p.nominal, p.min, p.max).is_some() {
                AT_BOUND
            } else {
                ' '
            };
            let _ = write!(s, "{:>width$.6e}{mark} ", v);
        }
        let mark = if i == c.best { "*" } else { " " };
        let restarts = match r.restarts {
            0 => String::new(),
            1 => " (after 1 restart off a plateau)".into(),
            n => format!(" (after {n} restarts off plateaus)"),
        };
        let _ = writeln!(
            s,
            "{:>13.6e} {:>6} {:>6} {mark} {}{restarts}",
            r.objective, r.evaluations, r.iterations, r.termination
        );
    }
    let _ = writeln!(
        s,
        "(* best run; {AT_BOUND} on a bound: within {:.0}% of its range from it)",
        100.0 * evidence::BOUND_TOLERANCE
    );
    let best = c.best_run();
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "best ({} from start {}):",
        best.method.name(),
        best.start
    );
    for (p, v) in c.campaign.free.iter().zip(&best.point) {
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
    for hit in evidence::bound_hits(&c.campaign.free, &best.point) {
        let _ = writeln!(s, "  note: {}", evidence::bound_sentence(&hit));
    }
    let _ = writeln!(
        s,
        "objective {:.6e} -> {:.6e} ({:.1}x lower)",
        c.nominal.objective,
        best.objective,
        c.nominal.objective / best.objective
    );
    // One line per compared series: per output, and per experiment when there are several.
    let several = !c.campaign.more.is_empty() || !c.campaign.experiment.is_empty();
    let mut k = 0;
    for part in c.objective.experiments() {
        let n = part.grid.len() as f64;
        let info = c.campaign.model.info();
        for &o in &part.outputs {
            let (before, after) = (c.nominal.sse[k], c.best_evaluation.sse[k]);
            k += 1;
            let name = if several {
                format!("{}: {}", part.name, info.outputs[o].name)
            } else {
                info.outputs[o].name.clone()
            };
            let _ = writeln!(
                s,
                "  rms {:<22} {:.4e} -> {:.4e}",
                name,
                (before / n).sqrt(),
                (after / n).sqrt()
            );
        }
    }
    let objectives: Vec<f64> = c.runs.iter().map(|r| r.objective).collect();
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
    let minima = c
        .clusters
        .iter()
        .filter(|k| k.kind == Stop::Minimum)
        .count();
    let stalled = |kind: Stop| {
        c.clusters
            .iter()
            .filter(|k| k.kind == kind)
            .map(|k| k.runs.len())
            .sum::<usize>()
    };
    let mut stalls = String::new();
    for (kind, words) in [
        (Stop::Plateau, "stalled on a plateau"),
        (Stop::Failures, "failed every simulation"),
    ] {
        let n = stalled(kind);
        if n > 0 {
            let _ = write!(stalls, ", {n} {words}");
        }
    }
    let _ = writeln!(
        s,
        "{} distinct minima found by {} runs{stalls}; {} evaluations, {} simulated, {} from \
         cache, {:.2} s",
        minima,
        c.runs.len(),
        c.evaluations(),
        c.stats.simulated,
        (c.evaluations() as u64).saturating_sub(c.stats.simulated),
        c.elapsed.as_secs_f64()
    );
    for k in c
        .clusters
        .iter()
        .filter(|k| k.kind == Stop::Minimum)
        .take(SHOWN_MINIMA)
    {
        let loose: Vec<String> = c
            .campaign
            .free
            .iter()
            .zip(&k.extent)
            .filter(|(p, (lo, hi))| hi - lo > LOOSE * (p.max - p.min))
            .map(|(p, (lo, hi))| format!("{} anywhere in [{lo:.4e}, {hi:.4e}]", p.name))
            .collect();
        let _ = writeln!(
            s,
            "  minimum {:.6e}: {} run{}{}",
            k.objective,
            k.runs.len(),
            if k.runs.len() == 1 { "" } else { "s" },
            if loose.is_empty() {
                String::new()
            } else {
                format!(", a valley: {}", loose.join(", "))
            }
        );
    }
    s
}

/// Minima listed under the summary, best first.
const SHOWN_MINIMA: usize = 5;

/// A cluster whose runs spread over more than this share of a parameter's range at one
/// objective is a valley in that parameter.
const LOOSE: f64 = 0.01;
