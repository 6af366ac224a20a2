//! The integration tests of `calib-worker`, in one test program: one module per subject
//! (the file of the same name), the shared helpers in `../common/`.
//!
//! A subject that measures the whole process (`fmu_archives.rs` counts every allocation) is
//! a program of its own beside this folder.

#[path = "../common/real_tool_fmus.rs"]
mod real_tool_fmus;
#[path = "../common/reference_fmus.rs"]
mod reference_fmus;

mod fmu_crosscheck;
mod fmu_inputs;
mod fmu_reference;
mod request_validation;
mod solver_fingerprints;
