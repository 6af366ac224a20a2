//! Bounds on what one simulation may ask for. A campaign file, `calib simulate` and a
//! worker's gRPC request are checked against these same numbers ([`crate::validate`]), so
//! that what one accepts the others never refuse.

use std::ops::RangeInclusive;

/// Largest gRPC message accepted or sent [bytes].
pub const MAX_MESSAGE_BYTES: usize = 64 << 20;
/// Most numbers one answer carries (56 MiB of doubles, the rest of [`MAX_MESSAGE_BYTES`] for
/// names, counts and failures): a `Simulate` answer's times and series, an `Evaluate`
/// answer's residuals. A request whose answer would hold more is refused before anything
/// is simulated.
pub const MAX_ANSWER_VALUES: usize = 7 << 20;
/// Most numbers of one record as a worker receives it (48 MiB of doubles): the times in
/// the window, each compared column, and each driving input's times and values. A campaign
/// whose record holds more is refused where it is checked (`calib calibrate`, submit), so
/// that what runs locally also runs on workers.
pub const MAX_RECORD_VALUES: usize = 6 << 20;
/// Most times in one output grid.
pub const MAX_TIMES: usize = 500_000;
/// Most points in one Evaluate request.
pub const MAX_POINTS: usize = 10_000;
/// Latest stop time [s].
pub const MAX_STOP_TIME: f64 = 1e6;
/// Step budgets of one simulation (accepted plus rejected steps).
pub const MAX_STEPS: RangeInclusive<u64> = 1..=10_000_000;
/// Relative tolerances of the ODE solver: below 1e-14 the error control asks for more than
/// double precision resolves, above 0.1 it controls nothing.
pub const RTOL: RangeInclusive<f64> = 1e-14..=0.1;
/// Absolute tolerances of the ODE solver, in the unit of each state.
pub const ATOL: RangeInclusive<f64> = 1e-300..=1e300;
/// Most Co-Simulation communication steps one simulation's communication step asks for
/// (from the start time to the stop time), as many as [`MAX_STEPS`] allows solver steps.
pub const MAX_COMMUNICATION_STEPS: f64 = 1e7;

// FMU archives (`.fmu` zip files), checked while they are read and inflated: a header's
// sizes and counts are never trusted (see `crate::fmu`). An upload is also bounded by
// `MAX_MESSAGE_BYTES`.

/// Largest FMU archive read [bytes, compressed].
pub const MAX_FMU_ARCHIVE_BYTES: u64 = 256 << 20;
/// Most entries (files and folders) in one FMU archive.
pub const MAX_FMU_ENTRIES: u64 = 10_000;
/// Largest file an FMU archive may inflate to [bytes].
pub const MAX_FMU_ENTRY_BYTES: u64 = 512 << 20;
/// Largest total an FMU archive may inflate to [bytes]; on a worker also at most the bound
/// of its FMU cache (`--fmu-cache-mib`).
pub const MAX_FMU_INFLATED_BYTES: u64 = 1 << 30;
/// Largest `modelDescription.xml` parsed [bytes].
pub const MAX_FMU_DESCRIPTION_BYTES: u64 = 32 << 20;

// The process an FMU's code runs in (`crate::fmu::host`, Linux).

/// Address space of the process running an FMU's code (`RLIMIT_AS`) [bytes]; override
/// with `CALIB_FMU_MEMORY_MIB`.
pub const FMU_HOST_MEMORY_BYTES: u64 = 4 << 30;
/// Default deadline of one simulation in an FMU's process [s] (override with
/// `CALIB_FMU_DEADLINE`); its CPU time (`RLIMIT_CPU`) is bounded by the same number.
pub const FMU_DEADLINE_SECONDS: f64 = 60.0;
