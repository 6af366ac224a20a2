//! The whole workflow on the Furuta record, and a CSV that does not parse.

use super::*;

#[test]
fn the_whole_workflow_in_a_browser_gives_the_values_of_calib_calibrate() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();

    // The reference: the same campaign from its file, in its own store.
    let reference = common::calib(&[
        "calibrate",
        repo().join("examples/furuta.toml").to_str().unwrap(),
        "--json",
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--db",
        dir.path().join("cli-db").to_str().unwrap(),
    ]);
    assert!(
        reference.status.success(),
        "{}",
        String::from_utf8_lossy(&reference.stderr)
    );
    let reference_text = String::from_utf8(reference.stdout).unwrap();
    let reference: Value = serde_json::from_str(&reference_text).unwrap();

    let ui = Ui::start(&dir.path().join("ui-db"));
    // Screenshots land in the build folder, so a test run leaves the tree clean;
    // `CALIB_SCREENSHOTS=docs/screenshots` refreshes README's.
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive(
        "workflow",
        &[&ui.url, data.to_str().unwrap(), shots.to_str().unwrap()],
        dir.path(),
    );

    // The columns of the record, found by the upload.
    assert_eq!(
        page["columns"],
        serde_json::json!(["arm_angle_rad", "pendulum_angle_rad"])
    );
    assert_the_calibration_is_calib_calibrates(&page, &reference_text, &reference, &ui);
    assert_the_diagnosis_finds_nothing_missing(&page);
    assert_the_sensitivity_is_calib_sensitivitys(&page, dir.path());
    assert_the_profiles_are_calib_profiles(&page, dir.path());
    assert_a_screenshot_of_each_tab(&shots);
}

/// The calibrated values on the page are `calib calibrate`'s (`reference`, `reference_text`
/// its JSON), bit for bit; the status, the live progress, the plots, the store's list and
/// the campaign file downloaded from `ui`.
fn assert_the_calibration_is_calib_calibrates(
    page: &Value,
    reference_text: &str,
    reference: &Value,
    ui: &Ui,
) {
    // The calibrated values on the page are calib calibrate's, bit for bit (the same
    // campaign gives the same runs); the text shows them to 8 significant digits.
    for name in ["armFriction", "pendulumFriction"] {
        let expected = best_parameter(reference_text, name);
        let shown = &page["calibrated"][name];
        let value: f64 = shown["value"].as_str().unwrap().parse().unwrap();
        assert_eq!(
            value, expected,
            "{name}: page {shown} vs calibrate {expected}; the campaign the page ran: {}",
            page["spec"]
        );
        let text: f64 = shown["text"].as_str().unwrap().parse().unwrap();
        assert!(
            ((text - expected) / expected).abs() < 1e-7,
            "{name}: shown {text} vs {expected}"
        );
        assert_eq!(shown["bound"], "inside", "{name}");
    }
    let at_best = &reference["runs_at_best"];
    let status = page["status"].as_str().unwrap();
    assert!(
        status.contains("finished")
            && status.contains(&format!(
                "{} of {} runs at the best",
                at_best["count"], at_best["of"]
            )),
        "{status}"
    );
    // Followed live: states of the running campaign, and a line per run in the progress plot.
    assert!(page["live_statuses"].as_u64().unwrap() >= 1, "{page}");
    assert!(
        page["progress_plot_lines"].as_u64().unwrap() >= 12,
        "{page}"
    );
    // A plot per output and the waterfall.
    let plots = page["plots"].to_string();
    for plot in ["armJoint.phi", "pendulumJoint.phi", "waterfall"] {
        assert!(plots.contains(plot), "{plots}");
    }
    // The campaign lists in the store, and its file downloads.
    assert!(
        page["campaigns_listed"]
            .to_string()
            .contains("furuta finished"),
        "{page}"
    );
    let link = page["toml_link"].as_str().unwrap();
    let (code, toml) = ui.get(&link[link.find("/ui/").unwrap()..]);
    assert_eq!(code, 200, "{toml}");
    assert!(
        toml.contains("armFriction")
            && toml.contains("pendulumFriction")
            && toml.contains("[search]"),
        "{toml}"
    );
}

/// The diagnosis of the clean record, and the campaign reopened from the store's list.
fn assert_the_diagnosis_finds_nothing_missing(page: &Value) {
    // The diagnosis of the clean record: nothing missing, said in a sentence, with the
    // candidates ranked and the plots before and after.
    let verdict = page["verdict"].as_str().unwrap();
    assert!(
        verdict.contains("Nothing is missing from the model"),
        "{verdict}"
    );
    assert_eq!(page["candidates"].as_array().unwrap().len(), 16, "{page}");
    let diagnosis_plots = page["diagnosis_plots"].to_string();
    for plot in [
        "fit_armJoint.phi",
        "residual_pendulumJoint.phi",
        "autocorrelation",
    ] {
        assert!(diagnosis_plots.contains(plot), "{diagnosis_plots}");
    }
    // Reopened from the store's list (reached by keyboard), the same values.
    for name in ["armFriction", "pendulumFriction"] {
        assert_eq!(
            page["reopened"][name], page["calibrated"][name]["value"],
            "{name}"
        );
    }
}

/// The sensitivity analysed on the page before calibrating, against `calib sensitivity`'s
/// (run in `dir`).
fn assert_the_sensitivity_is_calib_sensitivitys(page: &Value, dir: &std::path::Path) {
    // The sensitivity analysed on the page before calibrating is `calib sensitivity`'s on
    // the campaign file (the same 128 samples, seed 1): the same sentence, the same flags,
    // the total indices shown to 3 digits.
    let cli = common::calib(&[
        "sensitivity",
        repo().join("examples/furuta.toml").to_str().unwrap(),
        "--samples",
        "128",
        "--json",
        "--db",
        dir.join("sensitivity-db").to_str().unwrap(),
        "--out",
        dir.join("sensitivity").to_str().unwrap(),
    ]);
    let cli = common::json_of(&cli);
    let shown = &page["sensitivity"];
    assert_eq!(shown["conclusion"], cli["conclusion"], "{shown}");
    assert!(
        shown["status"].as_str().unwrap().contains("finished"),
        "{shown}"
    );
    let rows = shown["rows"].as_array().unwrap();
    let parameters = cli["parameters"].as_array().unwrap();
    assert_eq!(rows.len(), parameters.len(), "{shown}");
    for (row, p) in rows.iter().zip(parameters) {
        assert_eq!(row[0], p["name"], "{row}");
        let flag = if p["influential"].as_bool().unwrap() {
            "influential"
        } else {
            "can be held fixed"
        };
        assert_eq!(row[1], flag, "{row}");
        let total = p["total"].as_f64().unwrap();
        let text: f64 = row[2].as_str().unwrap().parse().unwrap();
        assert!(
            (text - total).abs() <= 5e-3 * total.abs().max(1e-12),
            "{row}: {total}"
        );
    }
    assert!(
        shown["plots"]
            .to_string()
            .contains("sensitivity of the objective"),
        "{shown}"
    );
}

/// The profiles on the page after the calibration, against `calib profile`'s on the
/// reference's store (in `dir`).
fn assert_the_profiles_are_calib_profiles(page: &Value, dir: &std::path::Path) {
    // The profiles on the page, after the calibration, are `calib profile`'s on the
    // reference's store (the same best point): the same intervals, bit for bit.
    let cli = common::calib(&[
        "profile",
        repo().join("examples/furuta.toml").to_str().unwrap(),
        "--json",
        "--db",
        dir.join("cli-db").to_str().unwrap(),
        "--out",
        dir.join("profile").to_str().unwrap(),
    ]);
    let cli = common::json_of(&cli);
    let shown = &page["profiles"];
    for p in cli["parameters"].as_array().unwrap() {
        let name = p["name"].as_str().unwrap();
        let row = &shown["rows"][name];
        for (side, key) in [("low", "ci_low"), ("high", "ci_high")] {
            let on_page: f64 = row[side].as_str().unwrap().parse().unwrap();
            assert_eq!(on_page, p[key].as_f64().unwrap(), "{name} {side}: {shown}");
        }
        assert_eq!(row["flag"], "identifiable", "{name}: {shown}");
    }
    assert!(
        shown["conclusion"]
            .as_str()
            .unwrap()
            .starts_with("Every profiled parameter is identifiable"),
        "{shown}"
    );
    assert_eq!(shown["plots"].as_array().unwrap().len(), 2, "{shown}");
}

/// A screenshot of each tab in `shots`.
fn assert_a_screenshot_of_each_tab(shots: &std::path::Path) {
    for tab in [
        "model",
        "measurement",
        "sensitivity",
        "calibration",
        "profiles",
        "diagnosis",
    ] {
        let png = std::fs::read(shots.join(format!("{tab}.png"))).unwrap();
        assert!(
            png.starts_with(b"\x89PNG") && png.len() > 10_000,
            "{tab}.png"
        );
    }
}

#[test]
fn a_broken_csv_shows_the_parsers_message_on_the_page() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken_rig.csv");
    std::fs::write(
        &broken,
        "time_s,arm_angle_rad\n0,0.1\n0.01,0.2\n0.02,zero\n",
    )
    .unwrap();
    let ui = Ui::start(&dir.path().join("db"));
    let page = drive("broken", &[&ui.url, broken.to_str().unwrap()], dir.path());
    let error = page["error"].as_str().unwrap();
    assert!(
        error.contains("broken_rig.csv") && error.contains("line 4") && error.contains("zero"),
        "{error}"
    );
    assert_eq!(page["status"], "", "{page}");
    // The arrow key moved the focus to the next tab.
    assert_eq!(page["focused_after_arrow"], "tab-measurement", "{page}");
}
