//! Bounds on what one measurement file may make the readers allocate. A MAT file is
//! refused with a message naming the bound before anything of that size is allocated.

/// Most bytes the compressed (miCOMPRESSED) elements of one MAT v5 file may inflate to,
/// in total: as much as an uncompressed upload may hold
/// (`campaigns::datasets::MAX_DATASET_BYTES`), so that compression never lets a file stand
/// for more data than it could hold plainly. Checked while inflating, against what the
/// stream really yields and against what each element declares before it is read.
pub const MAX_MAT_INFLATED_BYTES: usize = 256 << 20;

/// Most values (rows × columns, or the product of all dimensions) of one numeric MAT
/// variable, v4 or v5: 2^24 = 16,777,216 samples, 128 MiB as `f64`, 33 times what a
/// simulation's output grid may hold (`calib_worker::limits::MAX_TIMES`).
pub const MAX_MAT_VALUES: usize = 1 << 24;
