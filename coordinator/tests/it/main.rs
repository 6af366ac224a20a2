//! The integration tests of `calib-coordinator`, in one test program: one module per
//! subject (the file of the same name).
//!
//! A subject that measures the whole process (`measurement_memory.rs` counts every
//! allocation) is a program of its own beside this folder.

mod campaign_loader;
mod campaign_message;
