//! gRPC contracts of calib, generated from `calib/v1/*.proto`.
//!
//! Nothing but generated code lives here, and the JSON forms it names ([`json`]): the
//! services convert these types to domain types at their edge, so prost types never travel
//! further than a handler.

pub mod json;

/// Package `calib.v1`: the Simulator (workers) and Registry (coordinator) services.
pub mod v1 {
    tonic::include_proto!("calib.v1");
}

/// Descriptors of every message and service, for the gRPC reflection service.
pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("calib_descriptor");

/// The protocol version this build speaks (`ProtocolVersion::Current`).
pub const PROTOCOL_VERSION: u32 = v1::ProtocolVersion::Current as u32;
