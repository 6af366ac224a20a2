//! Effects written as formulas in the campaign file: a formula equal to a built-in effect
//! refits to the same optimum (in one process and over a worker), mistakes are refused
//! naming the field, the formula is part of the store's key, and a defined effect can be a
//! diagnosis candidate.

use crate::common::cluster::*;
use crate::common::*;
use calib_analysis::diagnosis::candidate_effects;
use calib_engine::calibration::{calibrate, calibrate_with_store, Calibration};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_engine::store::MemoryStore;
use std::path::Path;

/// The viscous-arm record (true viscous friction 0.002 N.m.s/rad) fitted with the two
/// frictions and `effect` free.
fn viscous_campaign(dir: &Path, file: &str, effect: &str) -> Result<Campaign, String> {
    let text = format!(
        r#"
name = "viscous"
[model]
name = "furuta"
stop_time = 40.0
[measurement]
file = "{}"
time_column = "time_s"
{FURUTA_OUTPUTS}{FURUTA_FRICTIONS}{effect}
[window]
start = 0.0
stop = 30.0
[search]
methods = ["nelder-mead"]
starts = 1
max_evaluations = 300
seed = 1
"#,
        repo()
            .join("examples/data/furuta_viscous_arm.csv")
            .display()
    );
    Campaign::load(&write(dir, file, &text)).map_err(|e| e.to_string())
}

const BUILT_IN: &str = r#"
[[effects]]
name = "viscous_friction.arm"
nominal = 0.001
min = 0.0
max = 1.0
"#;

fn defined(formula: &str) -> String {
    format!(
        r#"
[[effects]]
name = "damping.arm"
torque = "armJoint"
formula = "{formula}"
parameters = [ {{ name = "b", nominal = 0.001, min = 0.0, max = 1.0 }} ]
"#
    )
}

fn assert_same_optimum(built_in: &Calibration, user: &Calibration) {
    let (a, b) = (built_in.best_run(), user.best_run());
    for (x, y) in a.point.iter().zip(&b.point) {
        assert!(
            (x / y - 1.0).abs() <= 1e-9,
            "{:?} vs {:?}",
            a.point,
            b.point
        );
    }
    assert!((a.objective / b.objective - 1.0).abs() <= 1e-9);
}

#[test]
fn a_formula_for_viscous_friction_refits_as_the_built_in_effect() {
    let dir = tempfile::tempdir().unwrap();
    let built_in = viscous_campaign(dir.path(), "a.toml", BUILT_IN).unwrap();
    let user = viscous_campaign(dir.path(), "b.toml", &defined("-b * armJoint.w")).unwrap();
    assert_eq!(user.free.last().unwrap().name, "damping.arm.b");
    let a = calibrate(&built_in, LocalEvaluator, &Silent).unwrap();
    let b = calibrate(&user, LocalEvaluator, &Silent).unwrap();
    let best = b.best_run();
    println!(
        "built-in {:?} {:e}; formula {:?} {:e}",
        a.best_run().point,
        a.best_run().objective,
        best.point,
        best.objective
    );
    assert_same_optimum(&a, &b);
    // The record's viscous friction is found.
    assert!(
        (best.point[2] / 0.002 - 1.0).abs() < 0.05,
        "{:?}",
        best.point
    );

    // Over a worker: the formula travels as text and is compiled there.
    let cluster = TestCluster::start(1, 1);
    let remote = calibrate(&user, cluster.connect().evaluator(), &Silent).unwrap();
    assert!(cluster.simulations() > 0);
    assert_same_optimum(&a, &remote);
}

#[test]
fn the_formula_is_part_of_the_store_key() {
    let dir = tempfile::tempdir().unwrap();
    let store = MemoryStore::new();
    let first = viscous_campaign(dir.path(), "a.toml", &defined("-b * armJoint.w")).unwrap();
    let run = calibrate_with_store(&first, LocalEvaluator, &store, &Silent).unwrap();
    assert!(run.stats.simulated > 50, "{}", run.stats.simulated);
    // The same campaign replays entirely.
    let again = calibrate_with_store(&first, LocalEvaluator, &store, &Silent).unwrap();
    assert_eq!(again.stats.simulated, 0);
    assert_eq!(again.best_run().point, run.best_run().point);
    // Another formula is another model: nothing of the first is replayed.
    let changed = "-b * armJoint.w * abs(armJoint.w)";
    let other = viscous_campaign(dir.path(), "b.toml", &defined(changed)).unwrap();
    let fresh = calibrate_with_store(&other, LocalEvaluator, &store, &Silent).unwrap();
    let alone = calibrate_with_store(&other, LocalEvaluator, &MemoryStore::new(), &Silent);
    assert_eq!(fresh.stats.simulated, alone.unwrap().stats.simulated);
    assert!(fresh.stats.simulated > 50);
    assert_ne!(
        first.identity(&[0; 32]),
        other.identity(&[0; 32]),
        "campaign identities differ"
    );
}

/// The message of a campaign with `effect`, which must be refused.
fn refusal(effect: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    viscous_campaign(dir.path(), "bad.toml", effect).unwrap_err()
}

#[test]
fn mistakes_in_a_definition_name_the_field_and_suggest_the_name() {
    let e = refusal(&defined("-b * armJoint.ww"));
    assert!(
        e.contains(
            "`effects[0].formula`: at character 6: unknown name `armJoint.ww`; did you \
                    mean `armJoint.w`?"
        ),
        "{e}"
    );
    let e = refusal(&defined("-b * (armJoint.w"));
    assert!(e.contains("`effects[0].formula`: at character 17"), "{e}");
    let e = refusal(&defined("-b * sinus(armJoint.w)"));
    assert!(
        e.contains("unknown function `sinus`; did you mean `sin`?"),
        "{e}"
    );
    let e = refusal(&defined("-b * armJoint.w").replace("armJoint\"", "armJoin\""));
    assert!(
        e.contains(
            "`effects[0].torque`: model `furuta` has no torque `armJoin`; did you mean \
                    `armJoint`?"
        ),
        "{e}"
    );
    let e = refusal(&defined("-b * armJoint.w").replace("nominal = 0.001", "nominal = 2.0"));
    assert!(
        e.contains("`effects[0].parameters[0].nominal`: nominal 2 is outside its bounds [0, 1]"),
        "{e}"
    );
    let twice = format!(
        "{}{}",
        defined("-b * armJoint.w"),
        defined("-b * armJoint.phi")
    );
    let e = refusal(&twice);
    assert!(
        e.contains("`effects[1].name`: `damping.arm` is defined twice"),
        "{e}"
    );
    let clash = defined("-b * armJoint.w").replace("damping.arm", "viscous_friction");
    let clash = clash
        .replace("name = \"b\"", "name = \"arm\"")
        .replace("-b", "-arm");
    let e = refusal(&clash);
    assert!(
        e.contains("`effects[0].parameters[0].name`: `viscous_friction.arm` is already"),
        "{e}"
    );
    // Built-in effects listed before a definition keep their place in the field names.
    let e = refusal(&format!("{BUILT_IN}{}", defined("-b * armJoint.vv")));
    assert!(e.contains("`effects[1].formula`"), "{e}");
}

#[test]
fn a_defined_effect_held_at_zero_is_a_diagnosis_candidate() {
    let dir = tempfile::tempdir().unwrap();
    let cogging = r#"
[[effects]]
name = "cogging.arm"
torque = "armJoint"
formula = "a * sin(k * armJoint.phi + c)"
fixed = true
parameters = [ { name = "a", nominal = 0.0, min = -0.02, max = 0.02 },
               { name = "k", nominal = 12, min = 1, max = 40 },
               { name = "c", nominal = 0.0, min = -3.1416, max = 3.1416 } ]
[diagnosis]
candidates = ["cogging.arm.a", "viscous_friction.arm"]
"#;
    let campaign = viscous_campaign(dir.path(), "c.toml", cogging).unwrap();
    assert_eq!(
        campaign.free.len(),
        2,
        "every parameter of the effect is fixed"
    );
    let k = campaign
        .model
        .info()
        .parameter_index("cogging.arm.k")
        .unwrap();
    assert_eq!(campaign.base[k], 12.0);
    let names: Vec<String> = candidate_effects(&campaign)
        .into_iter()
        .map(|c| c.name)
        .collect();
    assert_eq!(names, ["viscous_friction.arm", "cogging.arm.a"]);
}

#[test]
fn a_formula_that_is_not_a_number_fails_the_campaign_naming_it_locally_and_on_workers() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 2);
    let search = "methods = [\"nelder-mead\"]\nmax_evaluations = 30";
    for (place, formula, says) in [
        (
            "torque = \"armJoint\"",
            "b * sqrt(-1)",
            "the torque of effect `odd.arm` on `armJoint` is NaN (formula `b * sqrt(-1)`)",
        ),
        (
            "output = \"pendulumJoint.phi\"",
            "b / (time - 2)",
            "at t = 2 s: the term of effect `odd.arm` on `pendulumJoint.phi` is inf",
        ),
    ] {
        let effect = format!(
            "[[effects]]\nname = \"odd.arm\"\n{place}\nformula = \"{formula}\"\n\
             parameters = [ {{ name = \"b\", nominal = 0.001, min = 0.0, max = 1.0 }} ]\n[window]"
        );
        let text = clean_campaign(search).replacen("[window]", &effect, 1);
        let file = write(dir.path(), "odd.toml", &text);
        let file = file.to_str().unwrap();
        let workers = cluster.urls().join(",");
        for extra in [vec![], vec!["--workers", workers.as_str()]] {
            let out = dir.path().join("out");
            let db = dir.path().join(format!("db{}", extra.len()));
            let mut args = vec!["calibrate", file, "--out", out.to_str().unwrap()];
            args.extend(["--db", db.to_str().unwrap()]);
            args.extend(&extra);
            let run = calib(&args);
            let stderr = String::from_utf8_lossy(&run.stderr);
            assert_eq!(run.status.code(), Some(2), "{stderr}");
            assert!(
                stderr.contains("every simulation of the search failed"),
                "{stderr}"
            );
            assert!(stderr.contains(says), "{stderr}");
            assert!(!out.join("clean").exists(), "no result written");
        }
    }
}
