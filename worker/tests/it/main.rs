//! The integration tests of `calib-worker`, in one test program: one module per subject (the
//! file of the same name).

mod request_validation;
