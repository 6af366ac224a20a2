//! The forms say what will happen before a campaign starts.

use super::*;

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
