//! The integration tests of the `calib` package, in one test program: one module per
//! subject (the file of the same name), the shared harness in `common/`. One program links
//! the workspace once instead of once per file. A new subject is a file here and its `mod`
//! line below; it reaches the harness as `crate::common`. `cargo test --test it <file>::`
//! runs one subject.
//!
//! A subject that changes what the whole process shares (its environment, where its FMUs run)
//! is a program of its own beside this folder: `tests/fmu_containment.rs`.

mod common;
#[path = "../../model/tests/common/real_tool_fmus.rs"]
mod real_tool_fmus;
#[path = "../../model/tests/common/reference_fmus.rs"]
mod reference_fmus;

mod api;
mod architecture;
mod campaign_history;
mod campaign_loader;
mod campaign_message;
mod campaign_requests;
mod cli;
mod cluster;
mod cluster_cli;
mod cluster_persistence;
mod cma_es;
mod code_size;
mod deploy;
mod diagnosis;
mod diagnosis_matrix;
mod discovery;
mod discovery_refit;
mod docs;
mod fmu;
mod fmu_api;
mod fmu_grid;
mod fmu_inputs;
mod fmu_output;
mod furuta_calibration;
mod furuta_experiments;
mod furuta_inputs;
mod hx_bench;
mod hx_calibration;
mod hx_diagnosis;
mod levenberg_marquardt;
mod persistence;
mod profile;
mod python_client;
mod security;
mod sensitivity;
mod sensitivity_at_fit;
mod slurm;
mod user_effects;
mod web_api;
mod web_door;
mod web_ui;
mod worker_service;
