//! A proposal found outside the library, shown and accepted into the campaign.

use super::*;

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
