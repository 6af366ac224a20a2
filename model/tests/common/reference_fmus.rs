//! The Modelica Association's Reference FMUs, built from their sources beside the repository
//! (`../shared/fmus/build.sh`) once per test process, with their reference results.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Folder holding `fmi2/` and `fmi3/` with `<Model>.fmu` and `<Model>_ref.csv`, or why
/// there is none. Under continuous integration (`calib_model::testing`) a missing build script or
/// compiler is a failure.
pub fn reference_fmus() -> Option<&'static Path> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let built = BUILT.get_or_init(|| {
        let script = Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .find_map(|d| {
                let s = d.join("../shared/fmus/build.sh");
                s.is_file().then_some(s)
            })
            .ok_or("../shared/fmus/build.sh is not beside the repository")?;
        let out = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("reference-fmus-{}", std::process::id()));
        let status = std::process::Command::new("bash")
            .arg(&script)
            .arg(&out)
            .stdout(std::process::Stdio::null())
            .status()
            .map_err(|e| format!("cannot run {}: {e}", script.display()))?;
        if !status.success() {
            return Err(format!(
                "{} failed ({status}); is a C compiler installed?",
                script.display()
            ));
        }
        Ok(out)
    });
    match built {
        Ok(dir) => Some(dir.as_path()),
        Err(why) => {
            calib_model::testing::skip(&format!("the reference FMUs: {why}"));
            None
        }
    }
}

/// A reference result: the header and the rows.
pub fn read_reference(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("a header")
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse::<f64>().expect("a number"))
                .collect()
        })
        .collect();
    (header, rows)
}
