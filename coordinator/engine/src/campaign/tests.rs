//! Campaign files resolved, and every kind of mistake located with its file, line and field.

use super::*;

const GOOD: &str = r#"
name = "clean"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
theta0 = 0.5235987755983

[measurement]
file = "data/furuta_clean.csv"
time_column = "time_s"

[[outputs]]
model = "armJoint.phi"
measured = "arm_angle_rad"
weight = 1.0

[[parameters]]
name = "armFriction"
nominal = 0.012
min = 0.0
max = 0.9

[window]
start = 0.0
stop = 40.0

[search]
methods = ["nelder-mead", "powell"]
starts = 3
max_evaluations = 300
seed = 7
"#;

fn parse(text: &str) -> Result<Campaign, CampaignError> {
    Campaign::parse(text, Path::new("/campaigns/c.toml"))
}

#[test]
fn a_good_campaign_resolves() {
    let c = parse(GOOD).unwrap();
    assert_eq!(c.name, "clean");
    assert_eq!(c.model.info().name, "furuta");
    assert_eq!(c.free[0].index, 0);
    assert_eq!(c.outputs[0].model_index, 0);
    assert_eq!(
        c.measurement_file,
        Path::new("/campaigns/data/furuta_clean.csv")
    );
    assert_eq!(c.search.methods, vec![Method::NelderMead, Method::Powell]);
    assert_eq!(c.window, (0.0, 40.0));
    let lm = parse(&GOOD.replacen("\"powell\"", "\"levenberg-marquardt\"", 1)).unwrap();
    assert_eq!(
        lm.search.methods,
        vec![Method::NelderMead, Method::LevenbergMarquardt]
    );
}

#[test]
fn cma_es_and_its_population_are_accepted_and_a_wrong_method_lists_it() {
    let text = GOOD.replace(
        "methods = [\"nelder-mead\", \"powell\"]",
        "methods = [\"cma-es\"]\ncma_population = 32",
    );
    let c = parse(&text).unwrap();
    assert_eq!(c.search.methods, vec![Method::CmaEs]);
    assert_eq!(c.search.cma_population, Some(32));
    assert_eq!(Method::CmaEs.name(), "cma-es");
    let e = error_for("\"powell\"]", "\"cma\"]");
    assert!(e.message.contains("`cma-es`"), "{e}");
    let e = error_for("seed = 7", "seed = 7\ncma_population = 1");
    assert_eq!(e.field, "search.cma_population", "{e}");
}

fn error_for(from: &str, to: &str) -> CampaignError {
    let text = GOOD.replacen(from, to, 1);
    assert_ne!(text, GOOD, "replacement `{from}` not found");
    parse(&text).unwrap_err()
}

#[test]
fn mistakes_are_located() {
    let e = error_for("name = \"furuta\"", "name = \"furuta2\"");
    assert_eq!(e.line, Some(4));
    assert!(e.to_string().contains("unknown model `furuta2`"), "{e}");

    let e = error_for("name = \"armFriction\"", "name = \"armFrction\"");
    assert_eq!(e.line, Some(19), "{e}");
    assert!(e.message.contains("no parameter `armFrction`"), "{e}");

    let e = error_for("model = \"armJoint.phi\"", "model = \"arm.phi\"");
    assert!(e.message.contains("no output `arm.phi`"), "{e}");

    let e = error_for("nominal = 0.012", "nominal = 1.5");
    assert!(e.message.contains("outside its bounds"), "{e}");

    let e = error_for("min = 0.0\nmax = 0.9", "min = 0.5\nmax = 0.5");
    assert!(e.message.contains("must be below max"), "{e}");

    let e = error_for("seed = 7", "seed = 7\ncolour = 3");
    assert!(e.message.contains("unknown field `colour`"), "{e}");
    assert_eq!(e.line, Some(33), "{e}");

    let e = error_for("\"powell\"", "\"simplex\"");
    assert!(e.message.contains("simplex"), "{e}");
    // The error lists the methods there are.
    assert!(e.message.contains("`levenberg-marquardt`"), "{e}");

    let e = error_for("theta0 = 0.5235987755983", "theta1 = 0.5");
    assert!(e.message.contains("no parameter `theta1`"), "{e}");

    let e = error_for("start = 0.0\nstop = 40.0", "start = 10.0\nstop = 5.0");
    assert_eq!(e.field, "window");

    // A value of the wrong type: its line and key, and a number as it was written.
    let e = error_for("seed = 7", "seed = 7\nscreening = 1e12");
    assert_eq!(
        (e.line, e.field.as_str()),
        (Some(33), "search.screening"),
        "{e}"
    );
    assert_eq!(
        e.message,
        "invalid type: floating point `1e12`, expected a whole number"
    );
    let e = error_for("max_evaluations = 300", "max_evaluations = 1e308");
    assert_eq!(e.field, "search.max_evaluations", "{e}");
    assert!(
        e.message.contains("`1e308`") && e.to_string().len() < 200,
        "{e}"
    );
    let e = error_for("name = \"armFriction\"", "name = 3");
    assert_eq!(e.field, "parameters[0].name", "{e}");
}

#[test]
fn solver_options_are_held_to_the_workers_limits() {
    let with = |solver: &str| format!("{GOOD}[solver]\n{solver}\n");
    let solver_line = GOOD.lines().count() + 1;
    let c = parse(&with("max_steps = 10000000\nrtol = 1e-6")).unwrap();
    assert_eq!((c.solver.max_steps, c.solver.rtol), (10_000_000, 1e-6));
    for (lines, field) in [
        ("max_steps = 10000001", "solver.max_steps"),
        ("max_steps = 0", "solver.max_steps"),
        ("rtol = 0.5", "solver.rtol"),
        ("atol = 0.0", "solver.atol"),
    ] {
        let e = parse(&with(lines)).unwrap_err();
        assert_eq!(e.field, field, "{lines}: {e}");
        assert!(
            e.line.is_some_and(|l| l >= solver_line),
            "{lines}: {e} (the [solver] table is on line {solver_line})"
        );
    }
}

#[test]
fn a_start_time_and_a_communication_step_apply_to_fmus_only() {
    let c = parse(GOOD).unwrap();
    assert_eq!(
        (c.solver.start_time, c.solver.communication_step),
        (0.0, None)
    );
    for (setting, field) in [
        ("start_time = 1.0", "model.start_time"),
        ("start_time = -1.0", "model.start_time"),
        ("step = 0.001", "model.step"),
    ] {
        let e = error_for("stop_time = 40.0", &format!("stop_time = 40.0\n{setting}"));
        assert_eq!(e.field, field, "{setting}: {e}");
        assert_eq!(e.line, Some(6), "{setting}: {e}");
    }
    let e = error_for("stop_time = 40.0", "stop_time = 40.0\nstep = 0.001");
    assert!(e.message.contains("Co-Simulation FMU"), "{e}");
    // A start of 0 is every model's.
    let c =
        parse(&GOOD.replacen("stop_time = 40.0", "stop_time = 40.0\nstart_time = 0.0", 1)).unwrap();
    assert_eq!(c.solver.start_time, 0.0);
}

#[test]
fn numbers_that_size_memory_are_held_to_the_limits_naming_the_field() {
    let search_line = GOOD.lines().position(|l| l == "[search]").unwrap() + 1;
    for (from, to, field, limit) in [
        ("starts = 3", "starts = 1000000000", "search.starts", "1000"),
        ("starts = 3", "starts = 1001", "search.starts", "1000"),
        (
            "seed = 7",
            "seed = 7\nscreening = 1000000000000",
            "search.screening",
            "65535",
        ),
        (
            "max_evaluations = 300",
            "max_evaluations = 1000001",
            "search.max_evaluations",
            "1000000",
        ),
    ] {
        let e = error_for(from, to);
        assert_eq!(e.field, field, "{e}");
        assert!(e.message.contains(limit), "{e}");
        assert!(e.line.is_some_and(|l| l >= search_line), "{e}");
    }
    let c = parse(&GOOD.replacen("starts = 3", "starts = 1000", 1)).unwrap();
    assert_eq!(c.search.starts, crate::limits::MAX_STARTS);

    let output = "[[outputs]]\nmodel = \"armJoint.phi\"\nmeasured = \"a\"\n";
    let e = parse(&format!("{GOOD}{}", output.repeat(32))).unwrap_err();
    assert_eq!(e.field, "outputs", "{e}");
    assert!(e.message.contains("33 is more than the 32"), "{e}");
    let parameter = "[[parameters]]\nname = \"armFriction\"\nmin = 0.0\nmax = 0.9\n";
    let e = parse(&format!("{GOOD}{}", parameter.repeat(64))).unwrap_err();
    assert_eq!(e.field, "parameters", "{e}");
    assert!(e.message.contains("65 is more than the 64"), "{e}");
    let e = parse(&format!("{GOOD}[diagnosis]\nrefit = 11\n")).unwrap_err();
    assert_eq!(e.field, "diagnosis.refit", "{e}");
}

#[test]
fn a_name_that_is_not_one_folder_name_is_refused() {
    for name in ["../../x", "/abs/x", "a/b", "..", ".calib-db", "a\\b"] {
        let e = error_for("name = \"clean\"", &format!("name = \"{name}\""));
        assert_eq!((e.field.as_str(), e.line), ("name", Some(2)), "{name}: {e}");
    }
    let long = "n".repeat(1_000_000);
    let e = error_for("name = \"clean\"", &format!("name = \"{long}\""));
    assert_eq!(e.field, "name");
    assert!(e.to_string().len() < 1000, "the name is echoed whole");
    // A file's stem names a campaign that names none, under the same rule.
    let unnamed = GOOD.replacen("name = \"clean\"\n", "", 1);
    let c = Campaign::parse(&unnamed, Path::new("/campaigns/rig 2.toml")).unwrap();
    assert_eq!(c.name, "rig 2");
    let e = Campaign::parse(&unnamed, Path::new("/campaigns/.hidden.toml")).unwrap_err();
    assert_eq!(e.field, "name", "{e}");
}

#[test]
fn unknown_names_suggest_the_nearest() {
    let e = error_for("name = \"armFriction\"", "name = \"armfriction\"");
    assert!(e.message.ends_with("did you mean `armFriction`?"), "{e}");
    assert!(!e.message.contains("pend_Izz"), "{e}");
    let e = error_for("model = \"armJoint.phi\"", "model = \"armJoint.ph\"");
    assert!(e.message.ends_with("did you mean `armJoint.phi`?"), "{e}");
    let e = error_for("name = \"furuta\"", "name = \"furtua\"");
    assert!(e.message.ends_with("did you mean `furuta`?"), "{e}");
    assert_eq!(e.line, Some(4));
}

#[test]
fn inputs_are_resolved_against_the_model() {
    let input = "[[inputs]]\nmodel = \"armTorque\"\nmeasured = \"u\"\n";
    let c = parse(&format!("{GOOD}{input}")).unwrap();
    assert_eq!(c.inputs[0].model_index, 0);
    assert_eq!(c.inputs[0].interpolation, Interpolation::Linear);
    assert_ne!(
        c.identity(&[0; 32]),
        parse(GOOD).unwrap().identity(&[0; 32])
    );
    let held = parse(&format!("{GOOD}{input}interpolation = \"hold\"\n")).unwrap();
    assert_eq!(held.inputs[0].interpolation, Interpolation::Hold);
    assert_ne!(held.identity(&[0; 32]), c.identity(&[0; 32]));

    let line = GOOD.lines().count() + 2;
    let e = parse(&format!("{GOOD}{}", input.replace("armTorque", "armTorqe"))).unwrap_err();
    assert_eq!(e.field, "inputs[0] (armTorqe)");
    assert_eq!(e.line, Some(line), "{e}");
    assert!(e.message.ends_with("did you mean `armTorque`?"), "{e}");
    let e = parse(&format!("{GOOD}{input}interpolation = \"cubic\"\n")).unwrap_err();
    assert!(e.message.contains("unknown interpolation `cubic`"), "{e}");
    let e = parse(&format!("{GOOD}{input}{input}")).unwrap_err();
    assert!(e.message.contains("driven twice"), "{e}");
}

const EXPERIMENTS: &str = r#"
name = "two"
[model]
name = "furuta"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
[[experiments]]
name = "swing"
file = "swing.csv"
window = { start = 0.0, stop = 20.0 }
fixed = { theta0 = 0.5 }
[[experiments]]
name = "driven"
file = "/data/driven.csv"
time_column = "t"
windows = [[0.0, 1.0], [2.0, 10.0]]
inputs = [ { model = "armTorque", measured = "u" } ]
[[experiments.parameters]]
name = "theta0"
nominal = 1.0
min = 0.0
max = 3.2
"#;

#[test]
fn experiments_share_the_free_parameters_and_keep_their_own() {
    let c = parse(EXPERIMENTS).unwrap();
    assert_eq!(c.experiment, "swing");
    assert_eq!(c.measurement_file, Path::new("/campaigns/swing.csv"));
    assert_eq!(c.windows, vec![(0.0, 20.0)]);
    let theta0 = c.model.info().parameter_index("theta0").unwrap();
    assert_eq!(c.base[theta0], 0.5);
    assert!(c.inputs.is_empty());
    let driven = &c.more[0];
    assert_eq!(driven.name, "driven");
    assert_eq!(driven.windows, vec![(0.0, 1.0), (2.0, 10.0)]);
    assert_eq!(driven.window, (0.0, 10.0));
    assert_eq!(driven.inputs[0].measured, "u");
    assert_eq!(driven.outputs[0].measured, "arm");
    assert_eq!(driven.base[theta0], 1.0);
    let names: Vec<&str> = c.free.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["armFriction", "theta0@driven"]);
    // The first experiment's vector leaves the other's own parameter alone.
    assert_eq!(c.full_parameters(&[0.1, 2.0])[theta0], 0.5);

    for (from, to, field) in [
        (
            "name = \"driven\"",
            "name = \"swing\"",
            "experiments[1] (swing)",
        ),
        (
            "name = \"theta0\"\nnominal = 1.0\nmin = 0.0\nmax = 3.2",
            "name = \"armFriction\"\nmin = 0.0\nmax = 0.5",
            "experiments[1] (driven).parameters[0] (armFriction)",
        ),
        (
            "nominal = 1.0",
            "nominal = 5.0",
            "experiments[1] (driven).parameters[0] (theta0)",
        ),
        (
            "[2.0, 10.0]]",
            "[0.5, 10.0]]",
            "experiments[1] (driven).windows[1]",
        ),
        (
            "theta0 = 0.5",
            "thetaO = 0.5",
            "experiments[0] (swing).fixed.thetaO",
        ),
        (
            "model = \"armTorque\"",
            "model = \"armTorq\"",
            "experiments[1] (driven).inputs[0] (armTorq)",
        ),
    ] {
        let e = parse(&EXPERIMENTS.replacen(from, to, 1)).unwrap_err();
        assert_eq!(e.field, field, "{to}: {e}");
        assert!(e.line.is_some(), "{e}");
    }
    let both = format!("{EXPERIMENTS}[measurement]\nfile = \"m.csv\"\n");
    let e = parse(&both).unwrap_err();
    assert!(e.message.contains("not both"), "{e}");
}

#[test]
fn disjoint_windows_in_the_one_record_form() {
    let c = parse(
        &GOOD
            .replacen("[window]\nstart = 0.0\nstop = 40.0", "", 1)
            .replacen(
                "name = \"clean\"",
                "name = \"clean\"\nwindows = [[0.0, 5.0], [10.0, 40.0]]",
                1,
            ),
    )
    .unwrap();
    assert_eq!(c.windows, vec![(0.0, 5.0), (10.0, 40.0)]);
    assert_eq!(c.window, (0.0, 40.0));
    assert_ne!(
        c.identity(&[0; 32]),
        parse(GOOD).unwrap().identity(&[0; 32])
    );
}

/// A client's campaign cannot make the objective test each sample against a million
/// intervals, nor an experiment compare more outputs than a campaign may.
#[test]
fn windows_and_an_experiments_outputs_are_bounded() {
    let windows: Vec<String> = (0..=crate::limits::MAX_WINDOWS)
        .map(|k| format!("[{}.0, {}.5]", k, k))
        .collect();
    let text = GOOD
        .replacen("[window]\nstart = 0.0\nstop = 40.0", "", 1)
        .replacen(
            "name = \"clean\"",
            &format!("name = \"clean\"\nwindows = [{}]", windows.join(", ")),
            1,
        );
    let e = parse(&text).unwrap_err();
    assert_eq!(e.field, "windows", "{e}");
    assert!(e.message.contains("1001 is more than the 1000"), "{e}");
    let output = "{ model = \"armJoint.phi\", measured = \"arm\" }";
    let outputs = vec![output; crate::limits::MAX_OUTPUTS + 1].join(", ");
    let text = EXPERIMENTS.replacen(
        "inputs = [",
        &format!("outputs = [{outputs}]\ninputs = ["),
        1,
    );
    let e = parse(&text).unwrap_err();
    assert_eq!(e.field, "experiments[1] (driven).outputs", "{e}");
    assert!(e.message.contains("33 is more than the 32"), "{e}");
}

#[test]
fn output_weights_sigmas_and_scales() {
    let with = |lines: &str| GOOD.replacen("weight = 1.0", lines, 1);
    let c = parse(&with("sigma = 0.5")).unwrap();
    assert_eq!(c.outputs[0].weight, 4.0);
    assert_eq!(c.outputs[0].scale, OutputScale::None);
    let c = parse(&with("weight = 2.0\nscale = \"variance\"")).unwrap();
    assert_eq!(c.outputs[0].weight, 2.0);
    assert_eq!(c.outputs[0].scale, OutputScale::Variance);
    let c = parse(&with("")).unwrap();
    assert_eq!(c.outputs[0].weight, 1.0);
    assert_ne!(
        parse(&with("scale = \"variance\""))
            .unwrap()
            .identity(&[0; 32]),
        parse(&with("")).unwrap().identity(&[0; 32])
    );

    for (lines, message) in [
        ("sigma = 0.0", "sigma 0 must be a finite number > 0"),
        ("sigma = -2.0", "sigma -2 must be a finite number > 0"),
        ("sigma = 1e-200", "must be a finite number > 0"),
        ("weight = 1.0\nsigma = 2.0", "not both"),
        (
            "sigma = 2.0\nscale = \"variance\"",
            "cannot be combined with `sigma`",
        ),
        ("scale = \"range\"", "unknown scale `range`"),
        ("weight = -1.0", "weight -1 must be"),
    ] {
        let e = parse(&with(lines)).unwrap_err();
        assert!(e.message.contains(message), "{lines}: {e}");
        assert_eq!(e.field, "outputs[0] (armJoint.phi)", "{lines}");
        // The offending key is on line 16 or 17 of the file.
        assert!(matches!(e.line, Some(16 | 17)), "{lines}: {e}");
    }
}
