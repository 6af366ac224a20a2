//! FMUs exported by real modelling tools (OpenModelica, Dymola, JModelica.org, PythonFMU),
//! gathered from the PyPI packages that keep them (`tests/python/real_tool_fmus.py`) once per
//! target folder, never copied into the repository.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Folder holding `gemseo-fmu/`, `modestpy/` and `aixcalibuha/` (see the script), or why
/// there is none. Under continuous integration (`calib_model::testing`) a missing Python or
/// an unreachable package index is a failure.
pub fn real_tool_fmus() -> Option<&'static Path> {
    static GATHERED: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let gathered = GATHERED.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .find(|d| d.join("tests/python/real_tool_fmus.py").is_file())
            .ok_or("tests/python/real_tool_fmus.py is not in the repository")?
            .to_path_buf();
        let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("real-tool-fmus");
        if out.join(".complete").exists() {
            return Ok(out);
        }
        // Several test processes may gather at once: each into its own folder, the first to
        // finish renames it into place.
        let mine = out.with_extension(format!("part-{}", std::process::id()));
        let output = std::process::Command::new("python3")
            .arg(root.join("tests/python/real_tool_fmus.py"))
            .arg(&mine)
            .output()
            .map_err(|e| format!("cannot run python3: {e}"))?;
        if !output.status.success() {
            return Err(format!(
                "tests/python/real_tool_fmus.py failed ({}): {}",
                output.status,
                String::from_utf8_lossy(&output.stderr).trim()
            ));
        }
        if std::fs::rename(&mine, &out).is_err() {
            let _ = std::fs::remove_dir_all(&mine);
        }
        if out.join(".complete").exists() {
            Ok(out)
        } else {
            Err(format!("{} is incomplete", out.display()))
        }
    });
    match gathered {
        Ok(dir) => Some(dir.as_path()),
        Err(why) => {
            calib_model::testing::skip(&format!("FMUs from real tools: {why}"));
            None
        }
    }
}
