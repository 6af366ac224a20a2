//! gRPC contracts of calib: generated from `calib/v1/*.proto`.
