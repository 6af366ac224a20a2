//! CPU time of this process, for the coordinator's cost per evaluation.

use std::time::Duration;

/// User plus system CPU time of every thread of this process so far (getrusage).
pub fn process_cpu() -> Duration {
    // SAFETY: getrusage writes into the struct it is given and reads nothing else.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        if libc::getrusage(libc::RUSAGE_SELF, &mut usage) != 0 {
            return Duration::ZERO;
        }
        usage
    };
    let time = |t: libc::timeval| Duration::new(t.tv_sec as u64, t.tv_usec as u32 * 1000);
    time(usage.ru_utime) + time(usage.ru_stime)
}

/// Microseconds of `cpu` per one of `count` things (NaN for none).
pub fn us_per(cpu: Duration, count: u64) -> f64 {
    if count == 0 {
        f64::NAN
    } else {
        cpu.as_secs_f64() * 1e6 / count as f64
    }
}
