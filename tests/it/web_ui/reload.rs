//! A page reloaded mid-campaign and after: it finds its work, edits and re-runs it.

use super::*;

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
    assert_the_reload_mid_campaign_keeps_the_work(&page, first);
    assert_the_reload_after_the_end_keeps_everything(&page);
    let result: Value =
        serde_json::from_str(page["state"]["result_json"].as_str().unwrap()).unwrap();
    assert_the_runs_table_is_result_jsons(&page, &result, &shot);
    assert_the_counts_are_calib_calibrates(&page, &result, &data, dir.path());
    assert_use_these_values_and_edit_and_rerun(&page, first);
}

/// Reloaded while campaign `first` ran: the work the page had is found again.
fn assert_the_reload_mid_campaign_keeps_the_work(page: &Value, first: &str) {
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
}

/// Finished, and reloaded again: everything as it was, with the result.
fn assert_the_reload_after_the_end_keeps_everything(page: &Value) {
    let after = &page["mid"]["after"];
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
}

/// The table of runs is `result`'s runs, and sorts; its screenshot is `shot`.
fn assert_the_runs_table_is_result_jsons(page: &Value, result: &Value, shot: &std::path::Path) {
    let reloaded = &page["reloaded"];
    // The table of runs is result.json's runs: methods, starts, evaluations, rounds,
    // objectives and parameters, each run named "<method> #<start>"; the runs at the best as
    // counted there.
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
    let png = std::fs::read(shot).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 5_000);
}

/// The counts on the page are the summary's of `calib calibrate` on the same campaign (run
/// in `dir` on `data`).
fn assert_the_counts_are_calib_calibrates(
    page: &Value,
    result: &Value,
    data: &std::path::Path,
    dir: &std::path::Path,
) {
    let (state, reloaded) = (&page["state"], &page["reloaded"]);
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
    let campaign = common::write(dir, "bench.toml", &text);
    let cli = common::calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        dir.join("cli-out").to_str().unwrap(),
        "--db",
        dir.join("cli-db").to_str().unwrap(),
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
}

/// "Use these values" and "Edit and re-run" (`first` the campaign edited).
fn assert_use_these_values_and_edit_and_rerun(page: &Value, first: &str) {
    let (state, reloaded) = (&page["state"], &page["reloaded"]);
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
