//! calib's PEST instruction reader against pyemu's (PEST++'s Python tools, no code shared):
//! PEST++'s own cases, and 200 drawn cases (output files of words and numbers in every
//! format, instruction files using every form on them), each read alike by both; and PEST's
//! phi of PEST++'s control file at its initial values, as pyemu computes it.

use calib_model::command::{ControlFile, Instructions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// pyemu's reading of each (instruction file, output file) pair, by lower-case observation
/// name; `None` (with the reason) where python3 or pyemu is missing.
fn pyemu(pairs: &[(PathBuf, PathBuf)]) -> Option<Vec<BTreeMap<String, f64>>> {
    let mut command = std::process::Command::new("python3");
    command.arg(repo().join("tests/python/pest_instructions.py"));
    for (ins, out) in pairs {
        command.arg(ins).arg(out);
    }
    let output = match command.output() {
        Ok(output) => output,
        Err(e) => {
            calib_model::testing::skip(&format!("python3 cannot run: {e}"));
            return None;
        }
    };
    if output.status.code() == Some(3) {
        calib_model::testing::skip(&format!(
            "pyemu is missing ({}): pip install pyemu",
            String::from_utf8_lossy(&output.stderr).trim()
        ));
        return None;
    }
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    Some(
        String::from_utf8(output.stdout)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect(),
    )
}

/// calib's reading, by lower-case observation name.
fn calib(ins: &Path, out: &Path) -> BTreeMap<String, f64> {
    let text = std::fs::read_to_string(ins).unwrap();
    let instructions = Instructions::parse(&text, &ins.display().to_string())
        .unwrap_or_else(|e| panic!("{e}\n{text}"));
    let output = std::fs::read_to_string(out).unwrap();
    let values = instructions
        .read(&output, &out.display().to_string())
        .unwrap_or_else(|e| panic!("{e}\n{text}\n{output}"));
    instructions
        .observations()
        .iter()
        .map(|o| o.to_ascii_lowercase())
        .zip(values)
        .collect()
}

#[test]
fn pestpps_cases_are_read_as_pyemu_reads_them() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/pestpp/tplins_test_1");
    let pairs: Vec<(PathBuf, PathBuf)> = [
        ("out1.dat.ins", "out1_copy.dat"),
        ("out1dum.dat.ins", "out1_copy.dat"),
        ("AOC_obs.txt.ins", "AOC_obs_copy.txt"),
    ]
    .iter()
    .map(|(i, o)| (data.join(i), data.join(o)))
    .collect();
    let Some(theirs) = pyemu(&pairs) else {
        return;
    };
    for ((ins, out), theirs) in pairs.iter().zip(theirs) {
        assert_eq!(calib(ins, out), theirs, "{}", ins.display());
    }
}

/// A small deterministic generator (SplitMix64).
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A whole number in `0..n`.
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A number as a model might print it.
fn printed(d: &mut Draw) -> String {
    let value = (d.next() % 2_000_000) as f64 / 1000.0 - 1000.0;
    let scale = 10f64.powi(d.below(9) as i32 - 4);
    let v = value * scale;
    match d.below(4) {
        0 => format!("{v:.3}"),
        1 => format!("{v:.6E}"),
        2 => format!("{v:.4e}"),
        _ => format!("{:.2}", v.abs()),
    }
}

/// One token of an output line, with its columns (1-based, inclusive).
struct Token {
    text: String,
    number: bool,
    from: usize,
    to: usize,
}

/// An output file of `lines` lines of unique words and numbers, and its tokens by line.
fn output(d: &mut Draw, case: usize, lines: usize) -> (String, Vec<Vec<Token>>) {
    let (mut text, mut rows) = (String::new(), Vec::new());
    for line in 0..lines {
        let mut row = String::new();
        let mut tokens = Vec::new();
        for k in 0..2 + d.below(6) {
            row.push_str(&" ".repeat(1 + d.below(4)));
            let (token, number) = if k % 2 == 0 || d.below(3) == 0 {
                (format!("w{case}x{line}y{k}"), false)
            } else {
                (printed(d), true)
            };
            let from = row.len() + 1;
            row.push_str(&token);
            tokens.push(Token {
                to: row.len(),
                from,
                text: token,
                number,
            });
        }
        text.push_str(&row);
        text.push('\n');
        rows.push(tokens);
    }
    (text, rows)
}

/// An instruction file reading some of the numbers of `rows`, each reached by one of the
/// forms: a secondary marker then `!obs!`, fixed and semi-fixed columns, whitespace, a
/// dummy; each line reached by a line advance or a primary marker. (pyemu has no tab `tN`;
/// the reader's own tests hold it.)
fn instructions(d: &mut Draw, rows: &[Vec<Token>]) -> String {
    let mut ins = String::from("pif @\n");
    let mut last = None::<usize>;
    let mut obs = 0;
    for (r, tokens) in rows.iter().enumerate() {
        if !tokens.iter().any(|t| t.number) || d.below(4) == 0 {
            continue;
        }
        let mut items = Vec::new();
        let mut cursor = 0; // columns before this one are read
                            // Reach the line: a line advance, or a primary marker on its first word.
        match (last, d.below(2)) {
            (_, 0) if !tokens[0].number => {
                items.push(format!("@{}@", tokens[0].text));
                cursor = tokens[0].to;
            }
            (Some(l), _) => items.push(format!("l{}", r - l)),
            (None, _) => items.push(format!("l{}", r + 1)),
        }
        last = Some(r);
        for (k, t) in tokens.iter().enumerate() {
            if !t.number || t.from <= cursor || d.below(3) == 0 {
                continue;
            }
            obs += 1;
            let name = if d.below(8) == 0 {
                "dum".to_string()
            } else {
                format!("o{obs}")
            };
            let before = if k > 0 { tokens[k - 1].to } else { 0 };
            let item = match d.below(5) {
                0 if k > 0 && !tokens[k - 1].number && before > cursor => {
                    format!("@{}@ !{name}!", tokens[k - 1].text)
                }
                1 => {
                    let from = t.from - d.below(t.from - before);
                    let to = t.to
                        + d.below(2)
                            .min(tokens.get(k + 1).map_or(0, |n| n.from - t.to - 1));
                    format!("[{name}]{from}:{to}")
                }
                2 => {
                    let from = t.from - d.below(t.from - before.max(cursor));
                    format!("({name}){from}:{}", t.from + d.below(t.to - t.from + 1))
                }
                // `w` from the cursor at the end of the token before lands on this one.
                3 | 4 if before == cursor => format!("w !{name}!"),
                _ => format!("[{name}]{}:{}", t.from, t.to),
            };
            items.push(item);
            cursor = t.to;
        }
        ins.push_str(&items.join(" "));
        ins.push('\n');
    }
    ins
}

#[test]
fn drawn_cases_are_read_as_pyemu_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let mut d = Draw(20261130);
    let mut pairs = Vec::new();
    for case in 0..200 {
        let lines = 3 + d.below(10);
        let (text, rows) = output(&mut d, case, lines);
        let ins = instructions(&mut d, &rows);
        let (i, o) = (
            dir.path().join(format!("{case}.ins")),
            dir.path().join(format!("{case}.out")),
        );
        std::fs::write(&i, ins).unwrap();
        std::fs::write(&o, text).unwrap();
        pairs.push((i, o));
    }
    let Some(theirs) = pyemu(&pairs) else {
        return;
    };
    let mut read = 0;
    for ((ins, out), theirs) in pairs.iter().zip(theirs) {
        let ours = calib(ins, out);
        assert_eq!(
            ours,
            theirs,
            "{}\n{}\n{}",
            ins.display(),
            std::fs::read_to_string(ins).unwrap(),
            std::fs::read_to_string(out).unwrap()
        );
        read += ours.len();
    }
    assert!(read > 500, "{read} observations read in all");
}

/// PEST++'s `tplins_test_1` run as its command runs it (its `forward_run.py` copies the
/// model's outputs into place): calib's phi from the control file, the instruction file and
/// the output equals pyemu's from the same files.
#[test]
fn pestpps_phi_at_its_initial_values_is_pyemus() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/pestpp/tplins_test_1");
    let dir = tempfile::tempdir().unwrap();
    for f in ["pest.pst", "out1.dat.ins"] {
        std::fs::copy(data.join(f), dir.path().join(f)).unwrap();
    }
    std::fs::copy(data.join("out1_copy.dat"), dir.path().join("out1.dat")).unwrap();
    let pst_file = dir.path().join("pest.pst");
    let pst = ControlFile::parse(&std::fs::read_to_string(&pst_file).unwrap(), "pest.pst").unwrap();
    let mut simulated = BTreeMap::new();
    for (ins, out) in &pst.instructions {
        simulated.extend(calib(&dir.path().join(ins), &dir.path().join(out)));
    }
    let ours = pst.phi(&simulated).unwrap();
    let output = std::process::Command::new("python3")
        .arg(repo().join("tests/python/pest_phi.py"))
        .arg(&pst_file)
        .arg(dir.path())
        .output();
    let output = match output {
        Ok(o) if o.status.code() == Some(3) => {
            return calib_model::testing::skip("pyemu is missing: pip install pyemu")
        }
        Ok(o) => o,
        Err(e) => return calib_model::testing::skip(&format!("python3 cannot run: {e}")),
    };
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let theirs: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(theirs["observations"], pst.observations.len());
    let theirs = theirs["phi"].as_f64().unwrap();
    assert!(
        ((ours - theirs) / theirs).abs() < 1e-12,
        "calib {ours}, pyemu {theirs}"
    );
    assert!((ours - 50.0).abs() < 1e-9, "{ours}");
}

/// PEST++'s case run for real: its folder copied into a private run folder, its templates
/// written with the initial values, its `forward_run.py` run (by python3) and its output read:
/// the observations give phi 50, and the run folder is gone.
#[test]
fn pestpps_case_runs_as_a_command_and_gives_its_phi() {
    use calib_model::command::{CommandModel, Template};
    if std::process::Command::new("python3")
        .arg("-c")
        .arg("")
        .status()
        .is_err()
    {
        return calib_model::testing::skip("python3 cannot run");
    }
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/pestpp/tplins_test_1");
    let read = |f: &str| std::fs::read_to_string(data.join(f)).unwrap();
    let pst = ControlFile::parse(&read("pest.pst"), "pest.pst").unwrap();
    let model = CommandModel {
        folder: data.clone(),
        // The case names `python`; Debian's is `python3`.
        command: pst.command.replace("python ", "python3 "),
        templates: pst
            .templates
            .iter()
            .map(|(t, f)| (Template::parse(&read(t), t).unwrap(), f.into()))
            .collect(),
        instructions: pst
            .instructions
            .iter()
            .map(|(i, f)| (Instructions::parse(&read(i), i).unwrap(), f.into()))
            .collect(),
        deadline: std::time::Duration::from_secs(60),
    };
    let scratch = tempfile::tempdir().unwrap();
    let values = model
        .run(&pst.model_values(&BTreeMap::new()), scratch.path())
        .unwrap();
    let names = model.instructions[0].0.observations();
    let simulated: BTreeMap<String, f64> = names
        .iter()
        .map(|n| n.to_ascii_lowercase())
        .zip(values)
        .collect();
    assert_eq!(
        pst.phi(&simulated).unwrap(),
        50.000000000000014_f64
            .min(50.0)
            .max(pst.phi(&simulated).unwrap())
    );
    assert!((pst.phi(&simulated).unwrap() - 50.0).abs() < 1e-9);
    assert_eq!(
        std::fs::read_dir(scratch.path()).unwrap().count(),
        0,
        "the run folder is removed"
    );
}
