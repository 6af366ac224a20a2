//! Compiles `calib/v1/*.proto` with a vendored `protoc`, so that a fresh machine needs
//! nothing but cargo, and writes the descriptor set the reflection service serves.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let protoc = protoc_bin_vendored::protoc_bin_path()?;
    // SAFETY: build scripts run single-threaded; prost-build reads PROTOC from the environment.
    unsafe { std::env::set_var("PROTOC", protoc) };
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    // JSON for the web app's routes (`calib-coordinator`'s `web` module transcodes each
    // RPC to a route taking and answering its messages as JSON, with the proto's field
    // names); absent fields take their proto3 defaults.
    tonic_prost_build::configure()
        .message_attribute(
            ".calib.v1",
            "#[derive(serde::Serialize, serde::Deserialize)] #[serde(default)]",
        )
        .enum_attribute(
            ".calib.v1",
            "#[derive(serde::Serialize, serde::Deserialize)]",
        )
        // The reports' JSON is the files the commands write: a parameter's statistics on the
        // objective at the top of its entry, a correlation matrix as a list of lists, and
        // intervals whose non-finite ends are null.
        .field_attribute(
            ".calib.v1.ParameterSensitivity.objective",
            "#[serde(flatten)]",
        )
        .field_attribute(
            ".calib.v1.DiagnosisFit.correlation",
            "#[serde(with = \"crate::json::rows\")]",
        )
        .field_attribute(
            ".calib.v1.SensitivityStatistics.first_ci",
            "#[serde(deserialize_with = \"crate::json::numbers\")]",
        )
        .field_attribute(
            ".calib.v1.SensitivityStatistics.total_ci",
            "#[serde(deserialize_with = \"crate::json::numbers\")]",
        )
        // Enums by name, as the proto's JSON mapping writes them (read by name or number).
        .field_attribute(
            ".calib.v1.CampaignState.phase",
            "#[serde(with = \"crate::json::campaign_phase\")]",
        )
        .field_attribute(
            ".calib.v1.DiagnosisState.phase",
            "#[serde(with = \"crate::json::campaign_phase\")]",
        )
        .field_attribute(
            ".calib.v1.AnalysisState.phase",
            "#[serde(with = \"crate::json::campaign_phase\")]",
        )
        .field_attribute(
            ".calib.v1.InputSeries.interpolation",
            "#[serde(with = \"crate::json::interpolation\")]",
        )
        .file_descriptor_set_path(out.join("calib_descriptor.bin"))
        .compile_protos(
            &[
                "calib/v1/simulator.proto",
                "calib/v1/registry.proto",
                "calib/v1/calibration.proto",
            ],
            &["."],
        )?;
    println!("cargo:rerun-if-changed=calib");
    Ok(())
}
