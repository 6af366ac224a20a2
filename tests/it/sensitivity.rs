//! `calib sensitivity`: which parameters of the examples matter, the same numbers on workers
//! as in one process, and every point kept in the evaluation store.

use crate::common::cluster::*;
use crate::common::*;
use calib_analysis::sensitivity::{analyse, Methods, Sensitivity, Settings, DEFAULT_SAMPLES};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::store::{MemoryStore, SledStore};

fn example(name: &str) -> Campaign {
    Campaign::load(&repo().join("examples").join(name)).unwrap()
}

fn index_of(s: &Sensitivity, parameter: &str) -> usize {
    s.parameters.iter().position(|p| p == parameter).unwrap()
}

fn total(s: &Sensitivity, quantity: usize, parameter: &str) -> f64 {
    s.quantities[quantity].sobol.as_ref().unwrap().total[index_of(s, parameter)]
}

#[test]
fn hx_all_the_air_side_pressure_drop_factor_can_be_held_fixed() {
    let campaign = example("hx_all.toml");
    let settings = Settings {
        methods: Methods::Sobol,
        samples: 256,
        seed: 1,
    };
    let s = analyse(&campaign, LocalEvaluator, &MemoryStore::new(), settings).unwrap();
    assert_eq!(s.quantities[1].name, "dp_ref");
    let airdp = total(&s, 0, "CF_Airdp");
    println!("{}", calib_analysis::sensitivity::report::table(&s));
    assert!(airdp < 0.01, "CF_Airdp total {airdp}");
    assert!(!s.influential(index_of(&s, "CF_Airdp")));
    assert!(s.fixable().contains(&"CF_Airdp"), "{:?}", s.fixable());
    assert!(s.conclusion().contains("CF_Airdp"), "{}", s.conclusion());
    // Over the whole box the objective is the pressure drop's huge errors far from any fit;
    // the heat-flow factor hardly moves it, yet carries most of the heat flow's variance.
    // It is not called fixable, and the advice says which output keeps it in.
    assert_eq!(s.quantities[2].name, "Qdot_refTotal");
    let airht = index_of(&s, "CF_AirHT");
    assert!(
        total(&s, 0, "CF_AirHT") < 0.01,
        "{}",
        total(&s, 0, "CF_AirHT")
    );
    assert!(
        total(&s, 2, "CF_AirHT") > 0.5,
        "{}",
        total(&s, 2, "CF_AirHT")
    );
    assert!(s.influential(airht));
    assert!(!s.fixable().contains(&"CF_AirHT"), "{:?}", s.fixable());
    assert_eq!(s.kept_for(airht), Some(2));
    assert!(
        s.conclusion()
            .contains("CF_AirHT is kept for Qdot_refTotal"),
        "{}",
        s.conclusion()
    );
    // CF_Refdp drives the pressure drop most, ahead of dp0 and mdot0.
    assert_eq!(s.parameters[s.most_influential(1)], "CF_Refdp");
    for other in ["dp0", "mdot0", "p0"] {
        assert!(
            total(&s, 1, "CF_Refdp") > total(&s, 1, other) + 0.05,
            "CF_Refdp {} vs {other} {}",
            total(&s, 1, "CF_Refdp"),
            total(&s, 1, other)
        );
    }
    assert_eq!(s.sobol_points, 256 * (8 + 2));
}

/// `examples/furuta.toml` as its frictions were first written: linear bounds [0, 0.9].
fn furuta_on_linear_bounds(dir: &std::path::Path) -> Campaign {
    let text = std::fs::read_to_string(repo().join("examples/furuta.toml"))
        .unwrap()
        .replace(
            "min = 1e-4\nmax = 0.9\nscale = \"log10\"\n",
            "min = 0.0\nmax = 0.9\n",
        )
        .replace(
            "file = \"data/",
            &format!("file = \"{}/", repo().join("examples/data").display()),
        );
    assert_eq!(text.matches("min = 0.0\n").count(), 2);
    assert!(!text.contains("log10\"\n"));
    Campaign::load(&write(dir, "furuta_linear.toml", &text)).unwrap()
}

#[test]
fn furuta_on_linear_bounds_only_the_pendulum_friction_drives_the_objective() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = furuta_on_linear_bounds(dir.path());
    let settings = Settings {
        methods: Methods::Both,
        samples: 256,
        seed: 1,
    };
    let s = analyse(&campaign, LocalEvaluator, &MemoryStore::new(), settings).unwrap();
    println!("{}", calib_analysis::sensitivity::report::table(&s));
    let pendulum = index_of(&s, "pendulumFriction");
    assert!(s.influential(pendulum));
    assert!(total(&s, 0, "pendulumFriction") > 0.9);
    // Over [0, 0.9] the bearings stick over most of the box and the pendulum's swing
    // outweighs the arm's by orders of magnitude: the arm friction's share of the
    // objective's variance stays below the threshold.
    assert!(total(&s, 0, "armFriction") < 0.01);
    let morris = s.quantities[0].morris.as_ref().unwrap();
    assert!(morris.mu_star[pendulum] > 100.0 * morris.mu_star[index_of(&s, "armFriction")]);
    // ...yet the arm friction moves the arm's angle as much as the pendulum friction does
    // (its Morris μ* on that output's contribution is of the same order): holding it fixed
    // would lose the arm's fit, so it is not called fixable, and the advice says why.
    let arm = index_of(&s, "armFriction");
    assert_eq!(s.quantities[1].name, "armJoint.phi");
    let on_arm = s.quantities[1].morris.as_ref().unwrap();
    assert!(
        on_arm.mu_star[arm] > 0.5 * on_arm.mu_star[pendulum],
        "{on_arm:?}"
    );
    assert!(s.fixable().is_empty(), "{:?}", s.fixable());
    assert_eq!(s.kept_for(arm), Some(1));
    let conclusion = s.conclusion();
    assert!(
        conclusion.starts_with("No parameter can be held fixed")
            && conclusion.contains("armFriction is kept for armJoint.phi")
            && !conclusion.contains("pendulumFriction is kept"),
        "{conclusion}"
    );
}

#[test]
fn furuta_both_frictions_are_influential_on_the_examples_log10_bounds() {
    // examples/furuta.toml searches the frictions on their logarithm over [1e-4, 0.9]:
    // the decades where the bearings stick no longer fill the box. At the default
    // samples, and at 512 where the arm's interval clears the threshold too.
    let campaign = example("furuta.toml");
    for samples in [DEFAULT_SAMPLES, 512] {
        let settings = Settings {
            methods: Methods::Both,
            samples,
            seed: 1,
        };
        let s = analyse(&campaign, LocalEvaluator, &MemoryStore::new(), settings).unwrap();
        println!("{}", calib_analysis::sensitivity::report::table(&s));
        for friction in ["armFriction", "pendulumFriction"] {
            assert!(
                s.influential(index_of(&s, friction)),
                "{friction} at {samples}"
            );
            assert!(total(&s, 0, friction) >= 0.01, "{friction} at {samples}");
        }
        assert!(s.fixable().is_empty());
        assert!(s.conclusion().starts_with("No parameter can be held fixed"));
        if samples == 512 {
            let arm = index_of(&s, "armFriction");
            assert!(s.quantities[0].sobol.as_ref().unwrap().total_ci[arm].0 > 0.01);
        }
    }
}

#[test]
fn sensitivity_on_workers_equals_the_local_one_and_a_rerun_simulates_nothing() {
    let campaign = example("furuta.toml");
    let settings = Settings {
        methods: Methods::Both,
        samples: 64,
        seed: 4,
    };
    let local = analyse(&campaign, LocalEvaluator, &MemoryStore::new(), settings).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let store = SledStore::open(&dir.path().join("db")).unwrap();
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let on_workers = analyse(&campaign, remote.evaluator(), &store, settings).unwrap();
    assert_eq!(local.quantities, on_workers.quantities);
    assert_eq!(local.stats.requested, on_workers.stats.requested);
    let simulations: u64 = cluster.workers.iter().map(|w| w.simulations()).sum();
    assert_eq!(simulations, on_workers.stats.simulated);
    assert!(on_workers.stats.simulated > 0);
    // The same analysis on the same store: every point is answered from it.
    let again = analyse(&campaign, LocalEvaluator, &store, settings).unwrap();
    assert_eq!(again.stats.simulated, 0);
    assert_eq!(again.stats.cached, again.stats.requested);
    assert_eq!(again.quantities, local.quantities);
}

#[test]
fn the_command_writes_the_table_the_json_and_a_chart_per_output() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = repo().join("examples/furuta.toml");
    let db = dir.path().join("db");
    let out = dir.path().join("out");
    let args = [
        "sensitivity",
        campaign.to_str().unwrap(),
        "--samples",
        "128",
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
    assert!(table.contains("No parameter can be held fixed"), "{table}");
    assert!(
        table.contains("contribution of pendulumJoint.phi"),
        "{table}"
    );
    let folder = out.join("furuta/sensitivity");
    for chart in [
        "sensitivity_objective.svg",
        "sensitivity_armJoint.phi.svg",
        "sensitivity_pendulumJoint.phi.svg",
    ] {
        let svg = std::fs::read_to_string(folder.join(chart)).unwrap();
        assert!(svg.contains("total index"), "{chart}");
    }
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("sensitivity.json")).unwrap())
            .unwrap();
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let printed = json_of(&calib(&json_args));
    // The second run is answered from the store, with the same numbers.
    assert_eq!(printed["parameters"], written["parameters"]);
    assert_eq!(printed["evaluations"]["simulated"], 0);
    let parameters = written["parameters"].as_array().unwrap();
    assert_eq!(parameters.len(), 2);
    for p in parameters {
        for key in ["mu_star", "sigma", "first", "total", "influential"] {
            assert!(!p[key].is_null(), "{key} in {p}");
        }
        for output in ["armJoint.phi", "pendulumJoint.phi"] {
            for key in ["mu_star", "sigma", "first", "total"] {
                assert!(
                    !p["outputs"][output][key].is_null(),
                    "{output} {key} in {p}"
                );
            }
        }
    }
    assert_eq!(parameters[0]["name"], "armFriction");
    assert_eq!(parameters[0]["influential"], true);
    assert_eq!(parameters[1]["influential"], true);
    // On a worker, into a fresh store: the same numbers, every point simulated there.
    let cluster = TestCluster::start(1, 1);
    let url = format!("http://{}", cluster.workers[0].address());
    let fresh = dir.path().join("db2");
    let mut remote_args = json_args.clone();
    remote_args[5] = fresh.to_str().unwrap();
    remote_args.extend(["--workers", url.as_str()]);
    let remote = json_of(&calib(&remote_args));
    assert_eq!(remote["parameters"], written["parameters"]);
    assert_eq!(
        remote["evaluations"]["simulated"].as_u64().unwrap(),
        cluster.workers[0].simulations()
    );
    assert!(cluster.workers[0].simulations() > 0);
}
