//! Two finished campaigns side by side.

use super::*;

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
