//! The campaigns of the diagnosis's robustness matrix: a record of the independent simulator
//! (or the real rig's) under one setting of bounds, methods and starts. `calib bench diagnose
//! --matrix` runs every cell; the test suite runs one cell per effect.

use std::path::Path;

/// Search settings: bounds, methods, starts.
pub const BOUNDS: [&str; 2] = ["linear", "log10"];
pub const METHODS: [&str; 3] = ["nm", "nm+powell", "all"];
pub const STARTS: [usize; 2] = [1, 4];

/// The objective the seed's tool chain reaches with its own model on the real record.
pub const SEED_REAL_OBJECTIVE: f64 = 2.729;

/// The `methods` list of a setting: "nm", "nm+powell" or "all" (the three of the matrix).
pub fn methods_toml(methods: &str) -> &'static str {
    match methods {
        "nm" => r#"["nelder-mead"]"#,
        "nm+powell" => r#"["nelder-mead", "powell"]"#,
        _ => r#"["nelder-mead", "powell", "differential-evolution"]"#,
    }
}

/// The `[search]` table of a setting: its methods from `starts` starts, 600 evaluations each.
pub fn search_toml(methods: &str, starts: usize) -> String {
    format!(
        "[search]\nmethods = {}\nstarts = {starts}\nmax_evaluations = 600\nseed = 1\n",
        methods_toml(methods)
    )
}

/// A free parameter on `bounds`: "linear" [0, 0.9], otherwise log10 on [`log_min`, 0.9].
pub fn parameter_toml(name: &str, nominal: f64, bounds: &str, log_min: f64) -> String {
    match bounds {
        "linear" => format!(
            "[[parameters]]\nname = \"{name}\"\nnominal = {nominal:?}\nmin = 0.0\nmax = 0.9\n"
        ),
        _ => format!(
            "[[parameters]]\nname = \"{name}\"\nnominal = {nominal:?}\nmin = {log_min:?}\nmax = 0.9\nscale = \"log10\"\n"
        ),
    }
}

/// A campaign over a free-swing record freeing both frictions (one held at 0 with `hold`).
pub fn synthetic_campaign(
    data: &Path,
    hold: Option<&str>,
    bounds: &str,
    methods: &str,
    starts: usize,
) -> String {
    let mut text = format!(
        r#"name = "matrix"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
{}
[measurement]
file = "{}"
time_column = "time_s"
[[outputs]]
model = "armJoint.phi"
measured = "arm_angle_rad"
[[outputs]]
model = "pendulumJoint.phi"
measured = "pendulum_angle_rad"
[window]
start = 0.0
stop = 30.0
[diagnosis]
holdout_start = 30.01
holdout_stop = 40.0
"#,
        hold.map_or(String::new(), |h| format!("{h} = 0.0")),
        data.display()
    );
    for (name, nominal) in [("armFriction", 0.012), ("pendulumFriction", 0.002)] {
        if Some(name) != hold {
            text.push_str(&parameter_toml(name, nominal, bounds, 1e-4));
        }
    }
    text.push_str(&search_toml(methods, starts));
    text
}

/// The real rig's record with the viscous-only model of `examples/furuta_real_naive.toml`.
pub fn naive_real_campaign(data: &Path, bounds: &str, methods: &str, starts: usize) -> String {
    let mut text = format!(
        r#"name = "naive"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
armFriction = 0.0
pendulumFriction = 0.0
[measurement]
file = "{}"
time_column = "time"
[[outputs]]
model = "armJoint.phi"
measured = "phi"
[[outputs]]
model = "pendulumJoint.phi"
measured = "theta"
[window]
start = 0.0
stop = 35.0
"#,
        data.display()
    );
    for (name, nominal) in [
        ("viscous_friction.arm", 0.001),
        ("viscous_friction.pendulum", 0.0001),
    ] {
        let p = parameter_toml(name, nominal, bounds, 1e-5);
        text.push_str(&p.replace("[[parameters]]", "[[effects]]"));
    }
    text.push_str(&search_toml(methods, starts));
    text
}
