//! The integration tests of `calib-model`, in one test program: one module per subject
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
mod pest_instructions;
mod solver_fingerprints;

/// FMUs exported by tools may keep simulation state in globals of their shared library
/// (OpenModelica's runtime does), so two instances of one such FMU running in one process at
/// once may corrupt each other. calib never does that (it runs each instance in a child
/// process of its own); the tests that run a tool's FMU in this process hold this lock
/// meanwhile, so that tests running side by side do not.
fn one_real_tool_fmu_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}
