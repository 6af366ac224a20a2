//! `calib profile`: profile likelihood intervals of the examples' parameters, beside the
//! linearised ones; the same numbers on workers as in one process, and a rerun answered
//! from the evaluation store.

use crate::common::cluster::*;
use crate::common::*;
use calib_analysis::profile::{
    profile, profile_through, report, BestFrom, ParameterProfile, Profiles, Settings,
};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::store::{MemoryStore, SharedDispatcher, SledStore};

fn example(name: &str) -> Campaign {
    Campaign::load(&repo().join("examples").join(name)).unwrap()
}

fn named<'a>(s: &'a Profiles, name: &str) -> &'a ParameterProfile {
    s.profiles.iter().find(|p| p.name == name).unwrap()
}

/// Both ends of the profile interval, which must exist.
fn interval(p: &ParameterProfile) -> (f64, f64) {
    (p.ci_low().unwrap(), p.ci_high().unwrap())
}

#[test]
fn furuta_both_frictions_are_identifiable_and_agree_with_the_linearised_intervals() {
    let campaign = example("furuta.toml");
    let s = profile(
        &campaign,
        &LocalEvaluator,
        &MemoryStore::new(),
        &Settings::default(),
    )
    .unwrap();
    println!("{}", report::table(&s));
    assert_eq!(s.best_from, BestFrom::Calibrated);
    let (arm, pendulum) = true_frictions();
    for (name, truth) in [("armFriction", arm), ("pendulumFriction", pendulum)] {
        let p = named(&s, name);
        assert!(p.identifiable(), "{name}: {:?}", p.conclusion());
        let (low, high) = interval(p);
        assert!(low < p.value && p.value < high, "{name}: [{low}, {high}]");
        let width = high - low;
        let linearised = p.linearised.ci_high - p.linearised.ci_low;
        println!(
            "{name}: profile [{low:e}, {high:e}], linearised [{:e}, {:e}]: ends {:.3e} and \
             {:.3e} of the width apart, widths {:e}",
            p.linearised.ci_low,
            p.linearised.ci_high,
            (low - p.linearised.ci_low).abs() / width,
            (high - p.linearised.ci_high).abs() / width,
            width / linearised - 1.0
        );
        let ratio = width / linearised;
        assert!(
            (0.5..=2.0).contains(&ratio),
            "{name}: widths {width} vs {linearised}"
        );
        // Both profiles are parabolas: the widths agree within 1e-3 (7.2e-5 and 2.4e-4
        // measured), each end within 0.5% of the width (0.13% to 0.29% measured).
        assert!(
            (ratio - 1.0).abs() < 1e-3,
            "{name}: widths {width} vs {linearised}"
        );
        for (end, linear) in [(low, p.linearised.ci_low), (high, p.linearised.ci_high)] {
            assert!(
                (end - linear).abs() < 5e-3 * width,
                "{name}: end {end} vs {linear}"
            );
        }
        // The record's simulator is not calib's: widened to twice its width about its
        // middle, the interval holds the true value.
        let middle = 0.5 * (low + high);
        assert!(
            (truth - middle).abs() <= width,
            "{name}: truth {truth} outside [{}, {}]",
            middle - width,
            middle + width
        );
    }
    // docs/profiles.md's rows and docs/results.md's best point, to their printed digits.
    let ends = |name: &str| {
        let p = named(&s, name);
        let (low, high) = interval(p);
        (
            p.value,
            low,
            high,
            p.linearised.ci_low,
            p.linearised.ci_high,
        )
    };
    for (name, printed) in [
        (
            "armFriction",
            [
                "0.0101239",
                "0.01012273",
                "0.01012505",
                "0.01012274",
                "0.01012506",
            ],
        ),
        (
            "pendulumFriction",
            [
                "0.00117005",
                "0.001169955",
                "0.001170145",
                "0.001169954",
                "0.001170144",
            ],
        ),
    ] {
        let (value, low, high, lin_low, lin_high) = ends(name);
        for (got, printed) in [value, low, high, lin_low, lin_high]
            .into_iter()
            .zip(printed)
        {
            assert_reads_as(got, printed, name);
        }
    }
    assert_reads_as(s.best_objective, "0.03275", "best objective");
    assert!(s.conclusions().is_empty());
    // No profile point beats the calibration's best by a meaningful amount.
    assert!(s.lowest > s.best_objective - 0.1 * s.threshold.delta);
}

#[test]
fn hx_all_the_air_side_pressure_drop_factor_is_open_on_both_sides() {
    // examples/hx_all.toml with a short search: the outputs never see the air-side
    // pressure drop, so its profile is flat around any point, and the test stays cheap.
    let text = std::fs::read_to_string(repo().join("examples/hx_all.toml"))
        .unwrap()
        .replace(
            "file = \"data/",
            &format!("file = \"{}/", repo().join("examples/data").display()),
        )
        .replace(
            "methods = [\"nelder-mead\", \"powell\", \"differential-evolution\"]\nstarts = 4\nmax_evaluations = 1500",
            "methods = [\"powell\"]\nstarts = 1\nmax_evaluations = 30",
        );
    assert!(text.contains("max_evaluations = 30"));
    let dir = tempfile::tempdir().unwrap();
    let campaign = write(dir.path(), "hx_all.toml", &text);
    let db = dir.path().join("db");
    let out = dir.path().join("out");
    let args = [
        "profile",
        campaign.to_str().unwrap(),
        "--parameter",
        "CF_Airdp",
        "--json",
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    let json = json_of(&calib(&args));
    assert_eq!(json["best"]["from"], "calibrated");
    let parameters = json["parameters"].as_array().unwrap();
    assert_eq!(parameters.len(), 1);
    let airdp = &parameters[0];
    assert_eq!(airdp["name"], "CF_Airdp");
    assert!(airdp["ci_low"].is_null(), "{airdp}");
    assert!(airdp["ci_high"].is_null(), "{airdp}");
    assert_eq!(airdp["identifiable"], false);
    assert_eq!(airdp["low"]["end"], "bound");
    assert_eq!(airdp["high"]["end"], "bound");
    // Flat: each step costs one evaluation, no re-optimisation, a handful of steps.
    let evaluations = airdp["low"]["evaluations"].as_u64().unwrap()
        + airdp["high"]["evaluations"].as_u64().unwrap();
    assert!(evaluations <= 8, "{evaluations} evaluations");
    let conclusions = json["conclusions"].as_array().unwrap();
    assert_eq!(conclusions.len(), 1);
    let sentence = conclusions[0].as_str().unwrap();
    assert!(
        sentence.starts_with("CF_Airdp is not identifiable")
            && sentence.contains("lower bound 0.1")
            && sentence.contains("upper bound 5"),
        "{sentence}"
    );
    let folder = out.join("hx_all/profile");
    assert!(folder.join("profile.json").exists());
    let svg = std::fs::read_to_string(folder.join("profile_CF_Airdp.svg")).unwrap();
    assert!(svg.contains("not identifiable"), "the plot's title says so");
}

#[test]
fn the_real_rig_with_the_seeds_model_has_both_frictions_identifiable() {
    let Some(_) = real_record() else { return };
    let campaign = example("furuta_real.toml");
    let s = profile(
        &campaign,
        &LocalEvaluator,
        &MemoryStore::new(),
        &Settings::default(),
    )
    .unwrap();
    println!("{}", report::table(&s));
    for name in ["armFriction", "pendulumFriction"] {
        let p = named(&s, name);
        assert!(p.identifiable(), "{name}: {:?}", p.conclusion());
        let (low, high) = interval(p);
        assert!(low < p.value && p.value < high, "{name}: [{low}, {high}]");
    }
    assert!((named(&s, "armFriction").value / 0.0100076 - 1.0).abs() < 1e-4);
}

#[test]
fn a_profile_on_workers_equals_the_local_one_and_a_rerun_simulates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(
        dir.path(),
        "clean.toml",
        &clean_campaign("methods = [\"powell\"]\nstarts = 2\nmax_evaluations = 400\nseed = 1"),
    );
    let campaign = Campaign::load(&file).unwrap();
    let settings = Settings::default();
    let local = profile(&campaign, &LocalEvaluator, &MemoryStore::new(), &settings).unwrap();
    let store = SledStore::open(&dir.path().join("db")).unwrap();
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let on_workers = profile(&campaign, &remote.evaluator(), &store, &settings).unwrap();
    assert_eq!(on_workers.best, local.best);
    assert_eq!(on_workers.threshold, local.threshold);
    assert_eq!(on_workers.profiles, local.profiles);
    assert_eq!(on_workers.stats, local.stats);
    let simulations: u64 = cluster.workers.iter().map(|w| w.simulations()).sum();
    let calibration = on_workers.calibration.unwrap();
    assert_eq!(
        simulations,
        calibration.simulated
            + on_workers.stats.evaluations.simulated
            + on_workers.stats.trajectories
    );
    assert!(on_workers.stats.evaluations.simulated > 0);
    // Again on the same store: the best point from the campaign's record, every profile
    // evaluation from the store; only the residual and the Jacobian are simulated.
    let again = profile(&campaign, &LocalEvaluator, &store, &settings).unwrap();
    assert_eq!(again.best_from, BestFrom::Store);
    assert!(again.calibration.is_none());
    assert_eq!(again.stats.evaluations.simulated, 0);
    assert_eq!(
        again.stats.evaluations.cached,
        again.stats.evaluations.requested
    );
    assert_eq!(again.stats.trajectories, 1 + 2 * 2);
    assert_eq!(again.profiles, local.profiles);
}

/// A profile through a dispatcher others share (a coordinator's), on a store without the
/// campaign's best point: the calibration it runs first goes through the same dispatcher,
/// so every point it simulates is that dispatcher's, and the numbers are the local ones.
#[test]
fn a_profile_through_a_shared_dispatcher_calibrates_through_it_too() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(
        dir.path(),
        "clean.toml",
        &clean_campaign("methods = [\"powell\"]\nstarts = 2\nmax_evaluations = 400\nseed = 1"),
    );
    let campaign = Campaign::load(&file).unwrap();
    let settings = Settings::default();
    let local = profile(&campaign, &LocalEvaluator, &MemoryStore::new(), &settings).unwrap();
    let store = std::sync::Arc::new(MemoryStore::new());
    let dispatcher = SharedDispatcher::start(std::sync::Arc::new(LocalEvaluator), store.clone());
    let evaluator = dispatcher.evaluator();
    let shared =
        profile_through(&campaign, &LocalEvaluator, &evaluator, &*store, &settings).unwrap();
    assert_eq!(shared.best_from, BestFrom::Calibrated);
    assert_eq!(shared.best, local.best);
    assert_eq!(shared.profiles, local.profiles);
    assert_eq!(shared.stats, local.stats, "the profile's own evaluations");
    let calibration = shared.calibration.unwrap();
    assert!(calibration.simulated > 0);
    // The calibration's points and the profile's, all through the shared dispatcher.
    assert_eq!(
        evaluator.stats().simulated,
        calibration.simulated + shared.stats.evaluations.simulated
    );
}

#[test]
fn the_command_prints_the_intervals_and_writes_a_plot_per_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(
        dir.path(),
        "clean.toml",
        &clean_campaign("methods = [\"powell\"]\nstarts = 2\nmax_evaluations = 400\nseed = 1"),
    );
    let db = dir.path().join("db");
    let out = dir.path().join("out");
    let args = [
        "profile",
        file.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    let run = calib(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let table = String::from_utf8_lossy(&run.stdout);
    assert!(table.contains("calibrated first"), "{table}");
    assert!(
        table.contains("Every profiled parameter is identifiable."),
        "{table}"
    );
    for name in ["armFriction", "pendulumFriction"] {
        let svg =
            std::fs::read_to_string(out.join(format!("clean/profile/profile_{name}.svg"))).unwrap();
        assert!(
            svg.contains("95% threshold") && svg.contains("linearised"),
            "{name}"
        );
    }
    let written: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("clean/profile/profile.json")).unwrap(),
    )
    .unwrap();
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let printed = json_of(&calib(&json_args));
    assert_eq!(printed["best"]["from"], "store");
    assert_eq!(printed["evaluations"]["simulated"], 0);
    assert_eq!(printed["parameters"], written["parameters"]);
    for p in printed["parameters"].as_array().unwrap() {
        assert_eq!(p["identifiable"], true);
        assert!(p["ci_low"].as_f64().unwrap() < p["value"].as_f64().unwrap());
        assert!(p["ci_high"].as_f64().unwrap() > p["value"].as_f64().unwrap());
        assert!(p["linearised"]["ci_low"].is_number());
    }
    // A parameter the campaign does not free is bad input.
    let wrong = calib(&[
        "profile",
        file.to_str().unwrap(),
        "--parameter",
        "armFrction",
        "--db",
        db.to_str().unwrap(),
    ]);
    assert_eq!(wrong.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&wrong.stderr).contains("armFrction"));
}

#[test]
fn diagnose_with_profile_gives_the_selected_effect_a_profile_interval() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let out = dir.path().join("out");
    let campaign = repo().join("examples/furuta_viscous_arm.toml");
    let json = json_of(&calib(&[
        "diagnose",
        campaign.to_str().unwrap(),
        "--profile",
        "--json",
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_eq!(
        json["selected"],
        serde_json::json!(["viscous_friction.arm"])
    );
    let profiles = json["profiles"].as_array().unwrap();
    assert_eq!(profiles.len(), 1, "{profiles:?}");
    let p = &profiles[0];
    assert_eq!(p["name"], "viscous_friction.arm");
    assert_eq!(p["identifiable"], true);
    let (low, high) = (
        p["ci_low"].as_f64().unwrap(),
        p["ci_high"].as_f64().unwrap(),
    );
    let linearised =
        p["linearised"]["ci_high"].as_f64().unwrap() - p["linearised"]["ci_low"].as_f64().unwrap();
    assert!((0.5..=2.0).contains(&((high - low) / linearised)), "{p}");
    // The record was made with 0.002.
    assert!(low < 0.002 && 0.002 < high, "[{low}, {high}]");
    assert!(json["profile_threshold"]["delta"].as_f64().unwrap() > 0.0);
}
