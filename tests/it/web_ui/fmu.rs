//! An FMU dropped or picked on the Model tab, simulated and calibrated.

use super::*;

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
