//! Levenberg–Marquardt on the examples: the optimum Nelder–Mead finds, in few rounds of
//! evaluations; bounds held; reruns replayed from the store; workers give the same bits.

use crate::common::cluster::*;
use crate::common::*;
use calib_engine::calibration::{calibrate, calibrate_with_store, Calibration};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::multistart::{RunOutcome, Stop};
use calib_engine::optim::problem::{Progress, Silent};
use calib_engine::store::{MemoryStore, Store};
use std::path::Path;
use std::sync::Mutex;

/// An example campaign with its data path made absolute and `search` as its `[search]`.
fn example(dir: &Path, name: &str, search: &str) -> Campaign {
    let text = std::fs::read_to_string(repo().join("examples").join(name)).unwrap();
    let data = repo().join("examples/data");
    let text = text.replace("file = \"data/", &format!("file = \"{}/", data.display()));
    let (head, rest) = text.split_once("[search]").unwrap();
    // The sections after `[search]` (the integrator's tolerance) stay.
    let tail = rest.find("\n[").map_or("", |i| &rest[i..]);
    let text = format!("{head}[search]\n{search}\n{tail}");
    Campaign::load(&write(dir, name, &text)).unwrap()
}

fn one_start(method: &str, max_evaluations: usize) -> String {
    format!("methods = [\"{method}\"]\nstarts = 1\nmax_evaluations = {max_evaluations}\nseed = 1")
}

/// Each batch a run evaluated: its size and the run's best objective after it.
#[derive(Default)]
struct Batches(Mutex<Vec<(usize, f64)>>);

impl Progress for Batches {
    fn evaluated(&self, _count: usize, _best_objective: f64) {}

    fn run_evaluated(&self, _run: usize, count: usize, run_best_objective: f64) {
        self.0.lock().unwrap().push((count, run_best_objective));
    }
}

fn calibrate_counting(campaign: &Campaign) -> (Calibration, Vec<(usize, f64)>) {
    let batches = Batches::default();
    let c = calibrate(campaign, LocalEvaluator, &batches).unwrap();
    (c, batches.0.into_inner().unwrap())
}

fn relative(a: f64, b: f64) -> f64 {
    (a / b - 1.0).abs()
}

/// Levenberg–Marquardt and Nelder–Mead from the nominal point of `name`: LM comes within 1%
/// of the better of the two in at most `rounds` rounds (README's figures) and fewer
/// evaluations, ends at an objective
/// no higher than Nelder–Mead's (to 1e-9, relative) with each parameter within
/// `parameter_tolerance` of Nelder–Mead's (relative), at a local minimum: moving any
/// parameter by ±10⁻⁴ of itself raises the objective. Returns LM's objective.
fn matches_nelder_mead(name: &str, parameter_tolerance: f64, rounds: usize) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let (lm, batches) = calibrate_counting(&example(
        dir.path(),
        name,
        &one_start("levenberg-marquardt", 400),
    ));
    let nm = calibrate(
        &example(dir.path(), name, &one_start("nelder-mead", 2000)),
        LocalEvaluator,
        &Silent,
    )
    .unwrap();
    let (a, b): (&RunOutcome, &RunOutcome) = (lm.best_run(), nm.best_run());
    let best = a.objective.min(b.objective);
    let within = batches.iter().position(|&(_, o)| o <= 1.01 * best).unwrap() + 1;
    println!(
        "{name}: LM {:?} objective {:.12e}, {} iterations ({} rounds), {} evaluations, 1% in \
         {within} rounds, `{}`; NM {:?} objective {:.12e}, {} iterations, {} evaluations, `{}`",
        a.point,
        a.objective,
        a.iterations,
        batches.len(),
        a.evaluations,
        a.termination,
        b.point,
        b.objective,
        b.iterations,
        b.evaluations,
        b.termination
    );
    assert_eq!(
        batches.len() as u64,
        a.iterations + 1,
        "one batch per iteration"
    );
    assert_eq!(
        batches.iter().map(|&(n, _)| n).sum::<usize>(),
        a.evaluations
    );
    assert!(within <= rounds, "1% of the optimum after {within} rounds");
    assert!(a.termination.starts_with("converged"), "{}", a.termination);
    assert_eq!(a.stop, Stop::Minimum);
    assert!(
        a.objective <= b.objective * (1.0 + 1e-9),
        "{} vs {}",
        a.objective,
        b.objective
    );
    for (x, y) in a.point.iter().zip(&b.point) {
        assert!(relative(*x, *y) <= parameter_tolerance, "{x} vs {y}");
    }
    assert!(
        a.evaluations < b.evaluations,
        "{} vs {}",
        a.evaluations,
        b.evaluations
    );
    for k in 0..a.point.len() {
        for share in [-1e-4, 1e-4] {
            let mut p = a.point.clone();
            p[k] *= 1.0 + share;
            let moved = lm.objective.evaluate(&p).objective;
            assert!(
                moved > a.objective,
                "parameter {k} × (1 {share:+}): {moved}"
            );
        }
    }
    a.objective
}

#[test]
fn levenberg_marquardt_finds_the_furuta_optimum_of_nelder_mead() {
    matches_nelder_mead("furuta.toml", 1e-6, 7);
}

/// From far below both frictions (0.005 each, on their log10 scales: the arm's half its
/// truth, the pendulum's four times), Levenberg–Marquardt ends in at most 25 rounds
/// (docs/performance.md: 23) at the optimum of the nominal start: the objective within
/// 1e-8 and the frictions within 1e-5 of it (relative).
#[test]
fn levenberg_marquardt_from_a_far_start_ends_within_25_rounds() {
    let dir = tempfile::tempdir().unwrap();
    let near = example(
        dir.path(),
        "furuta.toml",
        &one_start("levenberg-marquardt", 400),
    );
    let text = std::fs::read_to_string(near.source.as_ref().unwrap()).unwrap();
    let text = text
        .replace("nominal = 0.012", "nominal = 0.005")
        .replace("nominal = 0.002", "nominal = 0.005");
    let far = Campaign::load(&write(dir.path(), "far.toml", &text)).unwrap();
    let (far, batches) = calibrate_counting(&far);
    let near = calibrate(&near, LocalEvaluator, &Silent).unwrap();
    let (a, b) = (far.best_run(), near.best_run());
    println!(
        "far start: {} rounds, {} evaluations, objective {:.12e} ({:?}), `{}`; nominal start: {:.12e}",
        batches.len(),
        a.evaluations,
        a.objective,
        a.point,
        a.termination,
        b.objective
    );
    assert!(batches.len() <= 25, "{} rounds", batches.len());
    assert!(a.termination.starts_with("converged"), "{}", a.termination);
    assert!(relative(a.objective, b.objective) < 1e-8);
    for (x, y) in a.point.iter().zip(&b.point) {
        assert!(relative(*x, *y) < 1e-5, "{x} vs {y}");
    }
}

#[test]
fn levenberg_marquardt_finds_the_heat_exchanger_optimum_of_nelder_mead() {
    // The valley of CF_RefHT is flat: Nelder–Mead from the nominal point ends 5e-5 along it
    // (at an objective 4e-10 higher); the local-minimum check holds Levenberg–Marquardt's
    // point.
    let lm = matches_nelder_mead("hx.toml", 1e-4, 5);
    // The best of Nelder–Mead's multistart (the example's starts) is the same optimum: the
    // example's integrator tolerance (1e-10) leaves no noise in the objective for a start to
    // fall into below it (at 1e-6 the runs scattered by 2e-5 of it).
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 3\nmax_evaluations = 2000\nseed = 1";
    let nm = calibrate(
        &example(dir.path(), "hx.toml", search),
        LocalEvaluator,
        &Silent,
    )
    .unwrap();
    let best = nm.best_run().objective;
    println!("hx: LM from the nominal point {lm:.12e}, Nelder–Mead's best of 3 starts {best:.12e}");
    assert!(relative(lm, best) <= 1e-6, "{lm} vs {best}");
}

/// The heat exchanger's default mix against its former one (Nelder–Mead, Powell and
/// differential evolution), both replayed by `calib bench search` on 64 simulated workers:
/// at most half the wall time, at the same best objective (1e-6, relative).
#[test]
fn the_heat_exchangers_default_mix_takes_half_the_wall_time_on_64_workers() {
    let campaign = repo().join("examples/hx.toml");
    let out = calib(&[
        "bench",
        "search",
        "--campaigns",
        campaign.to_str().unwrap(),
        "--mix",
        "nelder-mead,powell,differential-evolution",
        "--mixes-only",
        "--workers",
        "64",
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert!(out.status.success(), "{stderr}");
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    let (former, default) = (&rows[0], &rows[1]);
    assert_eq!(
        former["label"],
        "mix (nelder-mead, powell, differential-evolution)"
    );
    assert!(
        default["label"]
            .as_str()
            .unwrap()
            .ends_with("(the campaign's)"),
        "{}",
        default["label"]
    );
    let wall = |row: &serde_json::Value| row["wall_seconds"]["64"].as_f64().unwrap();
    let best = |row: &serde_json::Value| row["best_objective"].as_f64().unwrap();
    assert!(
        wall(default) <= 0.5 * wall(former),
        "{} s against {} s",
        wall(default),
        wall(former)
    );
    assert!(
        relative(best(default), best(former)) <= 1e-6,
        "{} vs {}",
        best(default),
        best(former)
    );
}

#[test]
fn an_optimum_beyond_a_bound_ends_on_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    // The pendulum's true friction (0.00117 N·m·s) lies above its upper bound.
    let text = clean_campaign(&one_start("levenberg-marquardt", 400)).replace(
        "nominal = 0.002\nmin = 0.0\nmax = 0.9",
        "nominal = 0.0005\nmin = 0.0\nmax = 0.001",
    );
    let campaign = Campaign::load(&write(dir.path(), "bounded.toml", &text)).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let run = c.best_run();
    println!("{:?} {} `{}`", run.point, run.objective, run.termination);
    assert!(relative(run.point[1], 0.001) < 1e-12, "{:?}", run.point);
    assert!(
        run.termination.starts_with("converged"),
        "{}",
        run.termination
    );
    // The arm's friction makes up for it: better than at the nominal point.
    assert!(run.objective < c.nominal.objective);
}

fn lm_campaign(dir: &Path) -> Campaign {
    let search = "methods = [\"levenberg-marquardt\", \"nelder-mead\"]\nstarts = 2\n\
                  max_evaluations = 150\nseed = 3";
    Campaign::load(&write(dir, "lm.toml", &clean_campaign(search))).unwrap()
}

fn assert_same_runs(a: &Calibration, b: &Calibration) {
    let bits = |p: &[f64]| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(a.runs.len(), b.runs.len());
    for (x, y) in a.runs.iter().zip(&b.runs) {
        assert_eq!(
            bits(&x.point),
            bits(&y.point),
            "{} from {}",
            x.method,
            x.start
        );
        assert_eq!(x.objective.to_bits(), y.objective.to_bits());
        assert_eq!(x.evaluations, y.evaluations);
        assert_eq!(x.iterations, y.iterations);
        assert_eq!(x.termination, y.termination);
    }
    assert_eq!(a.best, b.best);
    assert_eq!(a.stats.requested, b.stats.requested);
}

#[test]
fn a_rerun_against_the_same_store_simulates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = lm_campaign(dir.path());
    let store = MemoryStore::new();
    let first = calibrate_with_store(&campaign, LocalEvaluator, &store, &Silent).unwrap();
    assert!(first.stats.simulated > 0);
    let again = calibrate_with_store(&campaign, LocalEvaluator, &store, &Silent).unwrap();
    assert_eq!(again.stats.simulated, 0);
    assert_same_runs(&first, &again);
    assert_eq!(store.stats().unwrap().evaluations, first.stats.simulated);
}

#[test]
fn a_cluster_run_equals_the_local_run() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = lm_campaign(dir.path());
    let local = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let remote_result = calibrate(&campaign, remote.evaluator(), &Silent).unwrap();
    assert_same_runs(&local, &remote_result);
    let simulations: u64 = cluster.workers.iter().map(|w| w.simulations()).sum();
    assert_eq!(simulations, remote_result.stats.simulated);
    assert!(local
        .runs
        .iter()
        .any(|r| r.method.name() == "levenberg-marquardt" && r.iterations > 2));
}

/// The residuals of a campaign of two experiments (one driven by a measured torque): each
/// experiment's in turn, squaring to the objective, whose bits they do not change; the same
/// bits from workers as in one process.
#[test]
fn residuals_of_several_experiments_are_concatenated_alike_everywhere() {
    use calib_engine::calibration::load_measurement;
    use calib_engine::evaluator::Evaluator;
    use calib_engine::objective::Objective;
    let dir = tempfile::tempdir().unwrap();
    let campaign = example(
        dir.path(),
        "furuta_experiments.toml",
        &one_start("levenberg-marquardt", 10),
    );
    let plain = Objective::new(&campaign, &load_measurement(&campaign).unwrap()).unwrap();
    let with = plain.with_residuals();
    assert_ne!(plain.fingerprint(), with.fingerprint());
    assert!(!plain.returns_residuals() && with.returns_residuals());
    let points = vec![vec![0.012, 0.002, 2.75], vec![0.0101, 0.00117, 2.9]];
    let local = LocalEvaluator.evaluate(&with, &points).unwrap();
    let samples: usize = with
        .experiments()
        .map(|e| e.grid.len() * e.outputs.len())
        .sum();
    for (point, e) in points.iter().zip(&local) {
        let alone = plain.evaluate(point);
        assert!(alone.residuals.is_empty());
        assert_eq!(alone.objective.to_bits(), e.objective.to_bits());
        assert_eq!(e.residuals.len(), samples);
        let squares: f64 = e.residuals.iter().map(|r| r * r).sum();
        assert!(
            relative(squares, e.objective) < 1e-12,
            "{squares} vs {}",
            e.objective
        );
    }
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let answers = remote.evaluator().evaluate(&with, &points).unwrap();
    for (a, b) in local.iter().zip(&answers) {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(a.objective.to_bits(), b.objective.to_bits());
        assert_eq!(bits(&a.residuals), bits(&b.residuals));
    }
}

/// On log10 scales (bounds [1e-5, 0.9], four decades and more) Levenberg–Marquardt, whose
/// differences and steps are taken on the scale, ends at the frictions it finds on linear
/// bounds (to 1e-6, relative) and never leaves the bounds; so does CMA-ES, to 1e-4.
#[test]
fn on_log10_scales_the_new_methods_end_at_the_linear_optimum() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = |file: &str, method: &str, log: bool| {
        let mut text = clean_campaign(&one_start(method, 3000));
        if log {
            text = text.replace(
                "min = 0.0\nmax = 0.9",
                "min = 1e-5\nmax = 0.9\nscale = \"log10\"",
            );
            assert_eq!(text.matches("log10").count(), 2);
        }
        Campaign::load(&write(dir.path(), file, &text)).unwrap()
    };
    let linear = calibrate(
        &campaign("lin.toml", "levenberg-marquardt", false),
        LocalEvaluator,
        &Silent,
    )
    .unwrap();
    for (method, tolerance) in [("levenberg-marquardt", 1e-6), ("cma-es", 1e-4)] {
        let c = campaign(&format!("{method}.toml"), method, true);
        let bounds = c.free.clone();
        let log = calibrate(&c, LocalEvaluator, &Silent).unwrap();
        let (a, b) = (log.best_run(), linear.best_run());
        println!(
            "{method} on log10 scales: {:?} {:.12e} `{}`; LM on linear bounds {:?} {:.12e}",
            a.point, a.objective, a.termination, b.point, b.objective
        );
        for (k, (x, y)) in a.point.iter().zip(&b.point).enumerate() {
            assert!(relative(*x, *y) <= tolerance, "{method}: {x} vs {y}");
            assert!(*x >= bounds[k].min && *x <= bounds[k].max);
        }
        assert!(relative(a.objective, b.objective) <= tolerance);
    }
}
