//! The worker's C part: FMI 2.0's variadic logger callback (see `csrc/fmi2_logger.c`).

fn main() {
    println!("cargo:rerun-if-changed=csrc/fmi2_logger.c");
    cc::Build::new()
        .file("csrc/fmi2_logger.c")
        .warnings(true)
        .compile("calib_fmi2_logger");
}
