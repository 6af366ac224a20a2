//! What every test suite of the workspace shares about where it runs.
//!
//! Tests that need something beside the repository (the real record, the Reference FMUs, a
//! container engine) skip where it is absent, saying why, except under continuous
//! integration, where nothing required may skip. One rule decides "under continuous
//! integration" for every crate's tests: `CI` set to anything but empty, `0` or `false`
//! (any case), as CI services set it (`CI=true`, `CI=1`).

/// The environment variable continuous integration sets.
pub const CI_VARIABLE: &str = "CI";

/// Whether `value`, the value of `CI` (`None` when unset), means "under continuous
/// integration".
pub fn ci_value_requires_everything(value: Option<&str>) -> bool {
    match value.map(str::trim) {
        None => false,
        Some(v) => !(v.is_empty() || v == "0" || v.eq_ignore_ascii_case("false")),
    }
}

/// Whether this process runs under continuous integration, where nothing required may skip.
pub fn ci_requires_everything() -> bool {
    let value = std::env::var_os(CI_VARIABLE);
    ci_value_requires_everything(value.as_deref().map(|v| v.to_str().unwrap_or("1")))
}

/// Skip a test that cannot run here, saying why; under continuous integration the same call
/// fails the test instead (at the caller's line).
#[track_caller]
pub fn skip(reason: &str) {
    assert!(
        !ci_requires_everything(),
        "required under CI, cannot skip: {reason}"
    );
    eprintln!("skipped: {reason}");
}

#[cfg(test)]
mod tests {
    use super::ci_value_requires_everything as ci;

    #[test]
    fn ci_is_any_value_but_empty_zero_or_false() {
        for on in [
            "true",
            "TRUE",
            "True",
            "1",
            "yes",
            "github-actions",
            " true ",
        ] {
            assert!(ci(Some(on)), "{on:?}");
        }
        for off in ["", " ", "0", "false", "FALSE", "False"] {
            assert!(!ci(Some(off)), "{off:?}");
        }
        assert!(!ci(None));
    }
}
