//! The web app in a real browser: `calib ui` drives headless Chromium through selenium
//! (`tests/python/web_ui.py`). The whole workflow on the Furuta record gives the values
//! `calib calibrate examples/furuta.toml` gives, read off the page, and leaves a screenshot
//! of each tab (in `docs/screenshots/` with `CALIB_SCREENSHOTS=docs/screenshots`); a CSV that does not parse shows the parser's message;
//! on `calib coordinator --http --token-file`, the page asks for the token, then works; an
//! FMU uploaded on the Model tab is simulated there and calibrated on the Calibration tab.
//! Skipped (with the reason printed) where Chromium, chromedriver or selenium is missing,
//! except under continuous integration (`CI` set), where that fails the test.

use crate::reference_fmus;

use crate::common;
use crate::common::repo;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Stdio};

/// Why a browser cannot be driven here, if it cannot.
fn browser_missing() -> Option<String> {
    let found = |name: &str| {
        std::env::var_os("PATH")
            .is_some_and(|path| std::env::split_paths(&path).any(|dir| dir.join(name).is_file()))
    };
    if !["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .any(|b| found(b))
    {
        return Some("no chromium on the PATH (apt-get install chromium)".into());
    }
    if !found("chromedriver") {
        return Some("no chromedriver on the PATH (apt-get install chromium-driver)".into());
    }
    match Command::new("python3")
        .args(["-c", "import selenium"])
        .output()
    {
        Err(e) => Some(format!("python3 cannot run: {e}")),
        Ok(out) if !out.status.success() => Some(format!(
            "selenium missing (pip install selenium): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        )),
        Ok(_) => None,
    }
}

/// `calib ui` serving on a port of its choosing; killed when dropped.
struct Ui {
    child: Child,
    url: String,
}

impl Ui {
    fn start(db: &std::path::Path) -> Ui {
        let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
            .args(["ui", "--no-open", "--listen", "127.0.0.1:0", "--db"])
            .arg(db)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start calib ui");
        let mut first = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut first)
            .expect("first line");
        let url = first
            .trim()
            .strip_prefix("calib ui at ")
            .unwrap_or_else(|| panic!("first line `{first}` does not say where the app is"))
            .to_string();
        assert!(
            url.starts_with("http://127.0.0.1:") && url.ends_with('/'),
            "{url}"
        );
        Ui { child, url }
    }

    /// `GET path` over plain HTTP/1.1: the status code and the body.
    fn get(&self, path: &str) -> (u16, String) {
        let host = self.url.trim_start_matches("http://").trim_end_matches('/');
        let mut stream = std::net::TcpStream::connect(host).expect("connect");
        write!(
            stream,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut answer = String::new();
        stream.read_to_string(&mut answer).unwrap();
        let (head, body) = answer.split_once("\r\n\r\n").unwrap_or((&answer, ""));
        let code = head
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        (code, body.to_string())
    }
}

impl Drop for Ui {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Run the page script in `mode` with `args`; what it read off the page.
fn drive(mode: &str, args: &[&str], dir: &std::path::Path) -> Value {
    let out = dir.join(format!("{mode}.json"));
    let run = Command::new("python3")
        .arg(repo().join("tests/python/web_ui.py"))
        .arg(mode)
        .args(args)
        .arg(&out)
        .output()
        .expect("run python3");
    assert!(
        run.status.success(),
        "web_ui.py {mode} failed:\n{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(&out).expect("page report")).expect("page report JSON")
}

/// The best value of parameter `name` in `calib calibrate --json`'s output, read from its
/// digits (shortest round-trip, as the page's are) with Rust's correctly rounded parser.
fn best_parameter(json: &str, name: &str) -> f64 {
    let best = &json[json.find("\"best\": {").expect("a best point")..];
    let key = format!("\"{name}\": ");
    let value = &best[best.find(&key).expect("the parameter") + key.len()..];
    let end = value.find([',', '\n', '}']).unwrap();
    value[..end].trim().parse().expect("a number")
}

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
    // The calibrated values on the page are calib calibrate's, bit for bit (the same
    // campaign gives the same runs); the text shows them to 8 significant digits.
    for name in ["armFriction", "pendulumFriction"] {
        let expected = best_parameter(&reference_text, name);
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
        dir.path().join("sensitivity-db").to_str().unwrap(),
        "--out",
        dir.path().join("sensitivity").to_str().unwrap(),
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
    // The profiles on the page, after the calibration, are `calib profile`'s on the
    // reference's store (the same best point): the same intervals, bit for bit.
    let cli = common::calib(&[
        "profile",
        repo().join("examples/furuta.toml").to_str().unwrap(),
        "--json",
        "--db",
        dir.path().join("cli-db").to_str().unwrap(),
        "--out",
        dir.path().join("profile").to_str().unwrap(),
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

/// `calib coordinator --http` with a token, serving on ports of its choosing; killed when
/// dropped.
struct TokenCoordinator {
    child: Child,
    url: String,
}

impl TokenCoordinator {
    fn start(dir: &std::path::Path, token_file: &std::path::Path) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
            .args([
                "coordinator",
                "--listen",
                "127.0.0.1:0",
                "--http",
                "127.0.0.1:0",
                "--token-file",
            ])
            .arg(token_file)
            .arg("--api-dir")
            .arg(dir.join("api"))
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start calib coordinator");
        let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
        let url = loop {
            let line = lines
                .next()
                .expect("the coordinator says where the app is")
                .expect("a line");
            if let Some(url) = line.strip_prefix("calib ui at ") {
                break url.to_string();
            }
        };
        TokenCoordinator { child, url }
    }
}

impl Drop for TokenCoordinator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_page_of_a_coordinator_with_a_token_asks_for_it_then_works() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let token = "a-token-of-32-characters-or-more!";
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, format!("{token}\n")).unwrap();
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&token_file, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
    let coordinator = TokenCoordinator::start(dir.path(), &token_file);
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive(
        "login",
        &[
            &coordinator.url,
            token_file.to_str().unwrap(),
            data.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert_eq!(page["tabs_hidden"], true, "{page}");
    assert_eq!(
        page["models_before"], 0,
        "nothing loaded before the login: {page}"
    );
    let wrong = page["wrong"].as_str().unwrap();
    assert!(wrong.contains("token"), "{page}");
    assert_eq!(page["login_hidden"], true, "{page}");
    assert!(page["model_plots"].as_u64().unwrap() >= 1, "{page}");
    assert!(
        page["measurement_status"]
            .as_str()
            .unwrap()
            .contains("samples"),
        "{page}"
    );
    assert!(page["measurement_plots"].as_u64().unwrap() >= 1, "{page}");
    assert_eq!(page["token_visible_to_scripts"], false, "{page}");
    // The session cookie is HttpOnly: scripts see none.
    assert!(
        !page["script_storage"]
            .as_str()
            .unwrap()
            .contains("calib_session"),
        "{page}"
    );
}

#[test]
fn an_fmu_dropped_or_picked_on_the_model_tab_is_simulated_and_calibrated() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let Some(fmus) = reference_fmus::reference_fmus() else {
        return;
    };
    let fmu = fmus.join("fmi2/VanDerPol.fmu");
    let dir = tempfile::tempdir().unwrap();
    // The record: VanDerPol at mu = 1.7, with noise, made by `calib simulate`.
    const TRUE_MU: f64 = 1.7;
    let record = dir.path().join("vanderpol.csv");
    common::van_der_pol_record(&fmu, &record, &[]);
    let ui = Ui::start(&dir.path().join("db"));
    let dropped = fmus.join("fmi2/BouncingBall.fmu");
    let page = drive(
        "fmu",
        &[
            &ui.url,
            fmu.to_str().unwrap(),
            record.to_str().unwrap(),
            dropped.to_str().unwrap(),
        ],
        dir.path(),
    );
    // Dropped on the Model tab: uploaded and chosen.
    assert!(
        page["dropped_chosen"]
            .as_str()
            .unwrap()
            .starts_with("BouncingBall.me@"),
        "{page}"
    );
    assert!(
        page["dropped_status"]
            .as_str()
            .unwrap()
            .starts_with("BouncingBall.fmu: FMU "),
        "{page}"
    );
    // Listed with its parameters and outputs, the default interface chosen.
    let chosen = page["chosen"].as_str().unwrap();
    assert!(chosen.starts_with("VanDerPol.me@"), "{page}");
    assert!(
        page["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p == "mu"),
        "{page}"
    );
    let outputs = page["outputs"].as_array().unwrap();
    assert_eq!(&outputs[..2], ["x0", "x1"], "{page}");
    // Simulated and plotted.
    assert!(
        page["simulated"]
            .as_str()
            .unwrap()
            .starts_with("simulated 20 s"),
        "{page}"
    );
    assert_eq!(page["model_plots"].as_array().unwrap().len(), 2, "{page}");
    // Calibrated: mu within 0.5% of the truth the record was made with (the tolerance of
    // the same campaign from its file in tests/it/fmu.rs).
    let mu: f64 = page["calibrated"]["mu"]
        .as_str()
        .expect("mu calibrated")
        .parse()
        .unwrap();
    eprintln!("calibrated on the page: mu = {mu}");
    assert!((mu / TRUE_MU - 1.0).abs() < 0.005, "mu = {mu}: {page}");
    assert!(
        page["calibration_status"]
            .as_str()
            .unwrap()
            .contains("finished"),
        "{page}"
    );
}

/// Two Furuta records fitted together on the page, the second driven by its measured arm
/// torque (mapped to the model's `armTorque` input, with its own start angle and window)
/// give the values `calib calibrate` gives the same campaign file, bit for bit; the results
/// show each experiment's fits, the driven one's input above them. The Model tab simulates
/// the model driven by the uploaded torque column.
#[test]
fn experiments_with_a_driven_input_on_the_page_give_the_values_of_calib_calibrate() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let swing = common::furuta_record(
        &dir.path().join("swing.csv"),
        std::f64::consts::FRAC_PI_6,
        10.0,
        3,
        None,
    );
    let driven = common::furuta_record(
        &dir.path().join("driven.csv"),
        0.2,
        10.0,
        4,
        Some(&common::arm_torque),
    );
    // The campaign the page is filled in with, as a file.
    let campaign = common::write(
        dir.path(),
        "pair.toml",
        &format!(
            r#"
name = "pair"
[model]
name = "furuta"
[model.parameters]
theta0 = 0.5235987755983
{}{}[[experiments]]
name = "swing"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = 10.0 }}
[[experiments]]
name = "driven"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = 10.0 }}
fixed = {{ theta0 = 0.2 }}
inputs = [ {{ model = "armTorque", measured = "motor_torque_Nm", interpolation = "linear" }} ]
[search]
methods = ["nelder-mead"]
starts = 2
max_evaluations = 150
seed = 1
"#,
            common::FURUTA_OUTPUTS,
            common::FURUTA_FRICTIONS,
            swing.display(),
            driven.display()
        ),
    );
    let reference = common::calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
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

    let ui = Ui::start(&dir.path().join("ui-db"));
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let page = drive(
        "experiments",
        &[
            &ui.url,
            swing.to_str().unwrap(),
            driven.to_str().unwrap(),
            shots.to_str().unwrap(),
        ],
        dir.path(),
    );
    println!("{page:#}");
    // The first record has no torque column to drive the input with.
    assert_eq!(
        page["first_input_choices"],
        serde_json::json!(["", "arm_angle_rad", "pendulum_angle_rad"])
    );
    // The Model tab drives the input by the uploaded column: its plot above the outputs',
    // and an arm that moves otherwise than undriven.
    let model = &page["model"];
    assert_eq!(
        model["driven"][0], "input armTorque driven by motor_torque_Nm",
        "{model}"
    );
    assert!(!model["undriven"].to_string().contains("input"), "{model}");
    assert_eq!(model["arm_differs"], true, "{model}");
    assert_eq!(model["overlaid_previous"], true, "{model}");
    let (arm, pendulum) = common::true_frictions();
    for (name, truth) in [("armFriction", arm), ("pendulumFriction", pendulum)] {
        let expected = best_parameter(&reference_text, name);
        let shown: f64 = page["calibrated"][name].as_str().unwrap().parse().unwrap();
        assert_eq!(
            shown.to_bits(),
            expected.to_bits(),
            "{name}: page {shown} vs calibrate {expected}"
        );
        assert!(
            (shown / truth - 1.0).abs() < 0.02,
            "{name}: {shown} vs {truth}"
        );
    }
    assert!(
        page["status"].as_str().unwrap().contains("finished"),
        "{page}"
    );
    // Each experiment's plots, the driven one's input first.
    let swing_plots = page["groups"]["Experiment swing"].to_string();
    for output in ["armJoint.phi", "pendulumJoint.phi"] {
        assert!(swing_plots.contains(output), "{swing_plots}");
    }
    let driven_plots: Vec<&str> = page["groups"]["Experiment driven"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert_eq!(driven_plots.len(), 3, "{driven_plots:?}");
    assert!(
        driven_plots[0].starts_with("driven: input armTorque"),
        "{driven_plots:?}"
    );
    assert!(page["plots"].to_string().contains("waterfall"), "{page}");
}

/// The first number before `marker` in `text`'s line that holds it.
fn number_before(text: &str, marker: &str) -> u64 {
    let at = text
        .find(marker)
        .unwrap_or_else(|| panic!("`{marker}` not in: {text}"));
    text[..at]
        .split(|c: char| !c.is_ascii_digit())
        .rfind(|w| !w.is_empty())
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no number before `{marker}` in: {text}"))
}

#[test]
fn the_page_reloaded_mid_campaign_and_after_finds_its_work_and_edits_and_reruns_a_campaign() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ui = Ui::start(&dir.path().join("ui-db"));
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let shot = shots.join("runs-table.png");
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive(
        "workbench",
        &[&ui.url, data.to_str().unwrap(), shot.to_str().unwrap()],
        dir.path(),
    );
    let first = page["first"].as_str().unwrap();
    assert_eq!(first.len(), 64, "{page}");

    // Reloaded while the campaign ran: the Calibration tab, the campaign and its dataset in
    // the URL, the form as it was submitted, the dataset, and the progress the server kept
    // (at least what there was before the reload).
    let mid = &page["mid"];
    assert_eq!(mid["running_when_reloaded"], true, "{mid}");
    let after = &mid["after"];
    assert_eq!(after["tab"], "tab-calibration");
    let hash = after["hash"].as_str().unwrap();
    assert!(
        hash.starts_with(&format!("#/calibration/campaign/{first}/dataset/")),
        "{hash}"
    );
    assert_eq!(after["form"], page["submitted_form"], "{page}");
    assert_eq!(
        after["columns"],
        serde_json::json!(["arm_angle_rad", "pendulum_angle_rad"])
    );
    assert!(after["progress_plots"].as_u64().unwrap() >= 1, "{after}");
    // The server's history goes on from where it was (thinned to half past its 200 points,
    // so it is counted in evaluations, not points).
    assert!(
        mid["evaluations_after"].as_u64().unwrap() >= mid["evaluations_before"].as_u64().unwrap(),
        "{mid}"
    );
    assert!(mid["history_before"].as_u64().unwrap() >= 1, "{mid}");
    assert!(mid["history_after"].as_u64().unwrap() >= 1, "{mid}");

    // Finished, and reloaded again: everything as it was, with the result.
    let finished = &page["finished"];
    let reloaded = &page["reloaded"];
    assert!(finished["result_shown"].as_bool().unwrap());
    for key in [
        "tab",
        "hash",
        "form",
        "dataset",
        "columns",
        "runs",
        "calibrated",
        "summary",
    ] {
        assert_eq!(reloaded[key], finished[key], "{key}");
    }
    assert_eq!(reloaded["form"], page["submitted_form"]);
    assert_eq!(reloaded["dataset"], after["dataset"]);
    assert!(reloaded["progress_plots"].as_u64().unwrap() >= 1);
    let state = &page["state"];
    assert_eq!(state["phase"], "CAMPAIGN_PHASE_FINISHED", "{state}");
    let history = state["history"].as_array().unwrap().len();
    assert!((1..=200).contains(&history), "{history}");

    // The table of runs is result.json's runs: methods, starts, evaluations, rounds,
    // objectives and parameters, each run named "<method> #<start>"; the runs at the best as
    // counted there.
    let result: Value = serde_json::from_str(state["result_json"].as_str().unwrap()).unwrap();
    let runs = result["runs"].as_array().unwrap();
    let table = reloaded["runs"].as_array().unwrap();
    assert_eq!(table.len(), runs.len());
    assert_eq!(table.len(), 6);
    for run in runs {
        let (method, start) = (
            run["method"].as_str().unwrap(),
            run["start"].as_u64().unwrap(),
        );
        let label = format!("{method} #{start}");
        let row = table
            .iter()
            .find(|r| r["label"] == label.as_str())
            .unwrap_or_else(|| panic!("{label} not in the table: {table:?}"));
        assert_eq!(row["method"], method);
        assert_eq!(row["start"], start);
        assert_eq!(row["evaluations"], run["evaluations"]);
        assert_eq!(row["rounds"], run["rounds"]);
        assert_eq!(row["iterations"], run["iterations"].to_string().as_str());
        assert_eq!(row["termination"], run["termination"]);
        let objective: f64 = row["objective"].as_str().unwrap().parse().unwrap();
        assert_eq!(objective, run["objective"].as_f64().unwrap(), "{label}");
        for (name, value) in run["parameters"].as_object().unwrap() {
            let shown: f64 = row["parameters"][name].as_str().unwrap().parse().unwrap();
            assert_eq!(shown, value.as_f64().unwrap(), "{label} {name}");
        }
    }
    let at_best = table.iter().filter(|r| r["at_best"] == true).count() as u64;
    assert_eq!(at_best, result["runs_at_best"]["count"].as_u64().unwrap());
    // Sorted by a heading, then the other way; by objective, best first.
    let up: Vec<u64> = serde_json::from_value(page["by_evaluations"].clone()).unwrap();
    let down: Vec<u64> = serde_json::from_value(page["by_evaluations_down"].clone()).unwrap();
    assert!(up.windows(2).all(|w| w[0] <= w[1]), "{up:?}");
    assert!(down.windows(2).all(|w| w[0] >= w[1]), "{down:?}");
    assert_eq!(page["sort_state"], "descending");
    let by_objective: Vec<f64> = serde_json::from_value(page["by_objective"].clone()).unwrap();
    assert!(
        by_objective.windows(2).all(|w| w[0] <= w[1]),
        "{by_objective:?}"
    );
    let png = std::fs::read(&shot).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 5_000);

    // The counts on the page are the summary's of `calib calibrate` on the same campaign,
    // and add up: evaluations = simulated + from the store.
    let text = std::fs::read_to_string(repo().join("examples/furuta.toml"))
        .unwrap()
        .replace("name = \"furuta\"\n\n[model]", "name = \"bench\"\n\n[model]")
        .replace(
            "file = \"data/furuta_clean.csv\"",
            &format!("file = {:?}", data.display().to_string()),
        )
        .replace(
            "methods = [\"nelder-mead\", \"powell\", \"differential-evolution\"]\nstarts = 4\nmax_evaluations = 2500",
            "methods = [\"nelder-mead\", \"powell\", \"differential-evolution\"]\nstarts = 2\nmax_evaluations = 2500",
        );
    assert!(text.contains("starts = 2\nmax") && text.contains("name = \"bench\""));
    let campaign = common::write(dir.path(), "bench.toml", &text);
    let cli = common::calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        dir.path().join("cli-out").to_str().unwrap(),
        "--db",
        dir.path().join("cli-db").to_str().unwrap(),
    ]);
    let summary = String::from_utf8(cli.stdout).unwrap();
    assert!(cli.status.success(), "{summary}");
    let (evaluations, simulated) = (
        result["evaluations"].as_u64().unwrap(),
        result["simulated"].as_u64().unwrap(),
    );
    assert_eq!(
        number_before(&summary, " evaluations,"),
        evaluations,
        "{summary}"
    );
    assert_eq!(
        number_before(&summary, " simulated,"),
        simulated,
        "{summary}"
    );
    let from_cache = number_before(&summary, " from cache");
    assert_eq!(evaluations, simulated + from_cache, "{summary}");
    assert_eq!(
        (state["simulated"].as_u64(), state["from_store"].as_u64()),
        (Some(simulated), Some(from_cache))
    );
    let shown = reloaded["summary"].as_str().unwrap();
    assert!(
        shown.contains(&format!(
            "{evaluations} evaluations ({simulated} simulated, {from_cache} from the store)"
        )),
        "{shown} vs {summary}"
    );

    // "Use these values": the calibrated values are the Model tab's now.
    assert_eq!(page["model_values"], reloaded["calibrated"], "{page}");
    assert!(page["model_tab_hash"]
        .as_str()
        .unwrap()
        .starts_with("#/model/"));

    // "Edit and re-run": a new campaign from the old one's spec with a narrower bound; it
    // finished, and the old one is unchanged.
    let second = page["second"].as_str().unwrap();
    assert_ne!(second, first);
    let rerun = &page["rerun"];
    assert_eq!(rerun["phase"], "CAMPAIGN_PHASE_FINISHED", "{rerun}");
    let max_of = |campaign: &Value, name: &str| {
        campaign["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .map(|p| p["max"].as_f64().unwrap())
    };
    assert_eq!(max_of(&rerun["campaign"], "armFriction"), Some(0.5));
    assert_eq!(max_of(&rerun["campaign"], "pendulumFriction"), Some(0.9));
    assert_eq!(
        max_of(&page["first_again"]["campaign"], "armFriction"),
        Some(0.9)
    );
    assert_eq!(rerun["campaign"]["search"], state["campaign"]["search"]);
    let rerun_result: Value = serde_json::from_str(rerun["result_json"].as_str().unwrap()).unwrap();
    let best = rerun_result["best"]["parameters"]["armFriction"]
        .as_f64()
        .unwrap();
    assert!(best <= 0.5, "{best}");
}

/// Run `tests/python/web_forms.py` in `mode` with `args`; what it read off the page.
fn drive_forms(mode: &str, args: &[&str], dir: &std::path::Path) -> Value {
    let out = dir.join(format!("{mode}.json"));
    let run = Command::new("python3")
        .arg(repo().join("tests/python/web_forms.py"))
        .arg(mode)
        .args(args)
        .arg(&out)
        .output()
        .expect("run python3");
    assert!(
        run.status.success(),
        "web_forms.py {mode} failed:\n{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(&out).expect("page report")).expect("page report JSON")
}

/// The page asks the server (ValidateCampaign) and shows each problem next to its field:
/// no method ticked gives the message next to the methods and starts nothing; a window past
/// the data's end is named next to the window before any Start; a fixed form shows no
/// message. An upload without a time column offers the file's columns with the time column
/// guessed; a failed upload keeps the good dataset and the outputs mapped onto it. The
/// Model tab's stop time follows the model.
#[test]
fn the_forms_say_what_will_happen_before_a_campaign_starts() {
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
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive_forms(
        "forms",
        &[&ui.url, data.to_str().unwrap(), broken.to_str().unwrap()],
        dir.path(),
    );

    // The stop time each model describes: furuta's 40 s record, the heat exchanger's
    // 300 s cycle.
    assert_eq!(page["stop_times"]["furuta"], "40", "{page}");
    assert_eq!(page["stop_times"]["hx_highfi"], "300", "{page}");
    assert_eq!(page["stop_times"]["hx_lowfi"], "300", "{page}");

    // The time column guessed, the file's columns offered to change it.
    assert_eq!(page["time_choice_shown"], true, "{page}");
    assert_eq!(page["time_chosen"], "time_s", "{page}");
    assert_eq!(
        page["time_offered"],
        serde_json::json!(["time_s", "arm_angle_rad", "pendulum_angle_rad"])
    );
    assert!(
        page["time_note"].as_str().unwrap().contains("guessed"),
        "{page}"
    );

    // The failed upload: its error, and the good dataset kept with its mappings.
    let error = page["broken_error"].as_str().unwrap();
    assert!(
        error.contains("broken_rig.csv")
            && error.contains("line 4")
            && error.contains("furuta_clean.csv, uploaded before, is still the measurement in use"),
        "{error}"
    );
    assert!(
        page["status_after_broken"]
            .as_str()
            .unwrap()
            .starts_with("furuta_clean.csv: 4001 samples"),
        "{page}"
    );
    assert_eq!(
        page["columns_after_broken"],
        serde_json::json!(["arm_angle_rad", "pendulum_angle_rad"])
    );
    assert!(
        page["context_after_broken"]
            .as_str()
            .unwrap()
            .contains("furuta_clean.csv"),
        "{page}"
    );
    assert_eq!(
        page["mapping_after_broken"],
        serde_json::json!({
            "armJoint.phi": ["arm_angle_rad", true],
            "pendulumJoint.phi": ["pendulum_angle_rad", true],
            "armJoint.w": ["", false],
        })
    );

    // No method: the message next to the methods and in the error box, not in the status
    // line; nothing started.
    assert_eq!(
        page["no_method_problems"],
        serde_json::json!({"methods": "choose at least one method"})
    );
    assert_eq!(page["no_method_next_to"], "methods", "{page}");
    assert!(
        page["no_method_error"]
            .as_str()
            .unwrap()
            .contains("choose at least one method"),
        "{page}"
    );
    assert_eq!(page["no_method_status"], "", "{page}");
    assert_eq!(page["started_without_method"], 0, "{page}");

    // The window past the data's end, named next to its stop before any Start; the stale
    // message about the methods gone.
    let late = page["late_window_problems"].as_object().unwrap();
    assert_eq!(late.len(), 1, "{page}");
    let message = late["window-stop"].as_str().unwrap();
    assert!(
        message.contains("50 s lies outside") && message.contains("time runs from 0 to 40 s"),
        "{message}"
    );
    assert_eq!(page["late_window_invalid"], "true", "{page}");
    assert_eq!(page["late_window_status"], "", "{page}");
    assert_eq!(page["started_with_late_window"], 0, "{page}");
    assert_eq!(page["problems_after_fix"], serde_json::json!({}), "{page}");
}

/// Two finished campaigns side by side: both names, their objectives and their parameters
/// with the range over the runs that reached the best, each the value of its result.json;
/// the fit plots of both in one row per output. The screenshot lands in `compare.png` (with
/// `CALIB_SCREENSHOTS=docs/img`, README's).
#[test]
fn two_finished_campaigns_are_compared_side_by_side() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ui = Ui::start(&dir.path().join("db"));
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let shot = shots.join("compare.png");
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive_forms(
        "compare",
        &[&ui.url, data.to_str().unwrap(), shot.to_str().unwrap()],
        dir.path(),
    );

    let ids: Vec<&str> = page["ids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(ids.len(), 2, "{page}");
    let results = &page["results"];
    let mut names: Vec<&str> = ids
        .iter()
        .map(|id| results[id]["name"].as_str().unwrap())
        .collect();
    for (header, name) in page["headers"].as_array().unwrap().iter().zip(&names) {
        assert!(header.as_str().unwrap().starts_with(name), "{page}");
    }
    names.sort();
    assert_eq!(names, ["arm-only", "both"], "{page}");
    // Each objective and parameter as its result holds it, digit for digit.
    for id in &ids {
        assert_eq!(page["objectives"][id], results[id]["objective"], "{page}");
    }
    let shown = page["parameters"].as_array().unwrap();
    assert_eq!(shown.len(), 3, "arm-only frees one, both two: {page}");
    for p in shown {
        let (id, name) = (
            p["campaign"].as_str().unwrap(),
            p["parameter"].as_str().unwrap(),
        );
        assert_eq!(p["value"], results[id]["parameters"][name], "{p}");
        let spread = &results[id]["spread"][name];
        let (low, high): (f64, f64) = (
            p["low"].as_str().unwrap().parse().unwrap(),
            p["high"].as_str().unwrap().parse().unwrap(),
        );
        assert_eq!(
            (low, high),
            (
                spread["min"].as_f64().unwrap(),
                spread["max"].as_f64().unwrap()
            )
        );
        let value: f64 = p["value"].as_str().unwrap().parse().unwrap();
        assert!(low <= value && value <= high, "{p}");
    }
    assert_eq!(
        page["not_calibrated"], 1,
        "pendulumFriction in arm-only: {page}"
    );
    // Each fitted output's fits overlaid on the measured data once, both campaigns named in
    // the legend with their objectives.
    let overlays = page["overlays"].as_array().unwrap();
    let outputs: Vec<&str> = overlays
        .iter()
        .map(|o| o["output"].as_str().unwrap())
        .collect();
    assert_eq!(outputs, ["armJoint.phi", "pendulumJoint.phi"], "{page}");
    for o in overlays {
        let legend = o["legend"].as_str().unwrap();
        assert!(
            legend.contains("arm-only: objective")
                && legend.contains("both: objective")
                && legend.contains("measured"),
            "{legend}"
        );
    }
    // One row per fitted output, both campaigns' plots in it.
    let rows = page["plot_rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{page}");
    for row in rows {
        assert_eq!(row["figures"], 2, "{row}");
    }
    assert!(shot.metadata().unwrap().len() > 10_000, "a screenshot");
}

/// The last state of a finished diagnosis with discovery, from the app's own route (its
/// Server-Sent Events end with the finished state).
fn diagnosis_with_discovery(ui: &Ui, id: &str) -> Value {
    let (code, body) = ui.get(&format!("/api/v1/Diagnose/{id}?discover=true"));
    assert_eq!(code, 200, "{body}");
    let last = body
        .lines()
        .filter_map(|l| l.strip_prefix("data:"))
        .next_back()
        .unwrap_or_else(|| panic!("no state in: {body}"));
    serde_json::from_str(last.trim()).unwrap()
}

/// A number the page holds in an attribute (JavaScript's shortest round-trip digits), as a
/// double.
fn page_number(v: &Value) -> f64 {
    v.as_str()
        .unwrap_or_else(|| panic!("{v} is not a page's number"))
        .parse()
        .unwrap()
}

/// On a record with a cogging torque on the arm (the independent simulator
/// `tests/python/furuta_extra_torque.py`), the Diagnosis tab asked to look outside the
/// library shows the server's proposal (the figures the server computed, digit for digit):
/// the formula in symbols and in words, the multiple 8, the amplitude interval holding the
/// truth 0.006, each term with its interval, the objective before and after the refit;
/// "Add to the campaign" puts the effect into the Calibration tab's form, and the campaign
/// started from it fits it, ending at least ten times lower than without it.
#[test]
fn a_proposal_found_outside_the_library_is_shown_and_accepted_into_the_campaign() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let Some((record, _)) = common::furuta_extra_torque_record(
        dir.path(),
        "cogging.csv",
        &["--cogging", "0.006", "--seed", "1"],
    ) else {
        return;
    };
    let ui = Ui::start(&dir.path().join("db"));
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let shot = shots.join("discovery.png");
    let page = drive(
        "discovery",
        &[&ui.url, record.to_str().unwrap(), shot.to_str().unwrap()],
        dir.path(),
    );
    println!("{page:#}");
    let first = page["first"]["id"].as_str().unwrap();
    let state = diagnosis_with_discovery(&ui, first);
    let found = &state["found_outside_the_library"];
    let server = &found["proposals"][0];
    let shown = &page["proposal"];

    // The proposal as the server made it: the formula in symbols and in words.
    assert_eq!(shown["formula"], server["formula"], "{shown}");
    assert!(
        server["formula"]
            .as_str()
            .unwrap()
            .contains("sin(8 * armJoint.phi)"),
        "{server}"
    );
    let words = shown["words"].as_str().unwrap();
    assert!(
        words.contains(server["formula_words"].as_str().unwrap())
            && words.contains("8 periods per turn of armJoint.phi"),
        "{words}"
    );
    // The harmonic: its multiple found (not told), its interval holding the truth.
    let h = &shown["harmonics"][0];
    assert_eq!(h["multiple"], "8", "{h}");
    let (low, high) = (page_number(&h["low"]), page_number(&h["high"]));
    assert!(low <= 0.006 && 0.006 <= high, "[{low}, {high}]");
    let s = &server["harmonics"][0];
    for (page_key, server_key) in [
        ("amplitude", "amplitude"),
        ("low", "ci_low"),
        ("high", "ci_high"),
    ] {
        assert_eq!(page_number(&h[page_key]), s[server_key].as_f64().unwrap());
    }
    // Each term with its interval, the server's numbers.
    let terms = shown["terms"].as_array().unwrap();
    assert_eq!(terms.len(), server["terms"].as_array().unwrap().len());
    for (t, s) in terms.iter().zip(server["terms"].as_array().unwrap()) {
        assert_eq!(t["parameter"], s["parameter"]);
        assert_eq!(t["function"], s["function"]);
        for (page_key, server_key) in [
            ("estimate", "estimate"),
            ("low", "ci_low"),
            ("high", "ci_high"),
        ] {
            assert_eq!(
                page_number(&t[page_key]),
                s[server_key].as_f64().unwrap(),
                "{t}"
            );
        }
    }
    // The objective before and after the refit, the server's, the proposal lowering it.
    let refit = &server["refit"];
    let (before, after) = (
        page_number(&shown["refit"]["before"]),
        page_number(&shown["refit"]["after"]),
    );
    assert_eq!(before, refit["objective_before"].as_f64().unwrap());
    assert_eq!(after, refit["objective_after"].as_f64().unwrap());
    assert!(after < 0.1 * before, "{before} -> {after}");
    assert_eq!(
        shown["toml"].as_str().unwrap().trim(),
        refit["effects_toml"].as_str().unwrap().trim()
    );

    // Accepted: the form holds the effect, and the campaign started from it fits it.
    let effect = &refit["effect"];
    let name = effect["name"].as_str().unwrap();
    assert_eq!(page["form"]["effects"], serde_json::json!([name]), "{page}");
    assert_eq!(page["form"]["formula"], effect["formula"], "{page}");
    let second = &page["second"];
    assert_eq!(
        second["defined_effects"],
        serde_json::json!([effect]),
        "{page}"
    );
    let free = second["free"].to_string();
    for p in effect["parameters"].as_array().unwrap() {
        let full = format!("{name}.{}", p["name"].as_str().unwrap());
        assert!(free.contains(&full), "{full} not free: {free}");
        assert!(page["result_rows"].get(&full).is_some(), "{page}");
    }
    let (without, with) = (
        page["first"]["objective"].as_f64().unwrap(),
        second["objective"].as_f64().unwrap(),
    );
    assert!(with < 0.1 * without, "objective {without} -> {with}");
}
