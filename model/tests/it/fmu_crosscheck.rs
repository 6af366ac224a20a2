//! FMUs exported by real tools and the Reference FMUs, simulated by calib and by FMPy
//! (`tests/python/fmpy_simulate.py`) through the same interface, onto the same grid at the
//! same tolerance: every output of calib within a stated fraction of its range of FMPy's.
//! And a Model Exchange FMU written here (`tests/lazy_fmu/`) that computes only when asked
//! for its derivatives or event indicators and decides its events on what it computed last,
//! against its closed form.

use crate::real_tool_fmus::real_tool_fmus;
use crate::reference_fmus::reference_fmus;
use calib_model::fmu::{self, Interface};
use calib_model::testing::skip;
use calib_model::Run;
use calib_model::{Model, SolverOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Model Exchange: calib's Dormand–Prince and FMPy's CVode, both at this relative tolerance.
const ME_RTOL: f64 = 1e-8;
/// Largest difference allowed, relative to the output's range, for Model Exchange (the worst
/// measured: 2.5e-6, VanDerPol's `der(x1)`; docs/fmu.md's table).
const ME_AGREEMENT: f64 = 3e-6;
/// The cases left out, each with the reason it is left out for (docs/fmu.md): a case left out
/// for another reason, or one more, fails the test, as does one of these being compared.
const LEFT_OUT: [(&str, &str, &str); 6] = [
    ("FMU3Model", "CS", "array variables"),
    ("Simple2R1C_linux64", "CS", "libgfortran.so.3"),
    (
        "HeatPumpSystemWithInput",
        "ME",
        "no binary for this platform",
    ),
    (
        "HeatPumpSystemWithInput",
        "CS",
        "no binary for this platform",
    ),
    ("StateSpace", "ME", "array variables"),
    ("StateSpace", "CS", "array variables"),
];
/// Cases compared output by output when every FMU is there (docs/fmu.md's table: 7 of
/// OpenModelica and Dymola through each interface they offer, 12 Reference FMUs through
/// both, 2.0 and 3.0, 37 in all).
const COMPARED: usize = 37;
/// Co-Simulation with the same communication step: the FMU's own solver both times.
const CS_AGREEMENT: f64 = 1e-12;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .to_path_buf()
}

fn options() -> SolverOptions {
    SolverOptions {
        rtol: ME_RTOL,
        atol: ME_RTOL * 1e-2,
        max_steps: 2_000_000,
        ..SolverOptions::default()
    }
}

/// One FMU to run through one interface.
struct Case {
    tool: String,
    model: String,
    version: String,
    interface: Interface,
    path: PathBuf,
}

/// What became of a case.
enum Outcome {
    /// The largest difference to FMPy relative to the range, per output (name, difference),
    /// and the number of grid times compared.
    Compared(Vec<(String, f64)>, usize),
    /// Not run here, and why (not a failure of calib).
    Left(String),
    /// calib failed where FMPy did not.
    Failed(String),
}

/// `attr="…"` of the model description's root element.
fn attribute(xml: &str, attr: &str) -> Option<String> {
    let root = &xml[xml.find("<fmiModelDescription")?..];
    let root = &root[..root.find('>')?];
    let at = root.find(&format!("{attr}="))? + attr.len() + 1;
    let quote = root[at..].chars().next()?;
    let rest = &root[at + 1..];
    Some(rest[..rest.find(quote)?].to_string())
}

fn description_xml(path: &Path) -> String {
    let file = std::fs::File::open(path).unwrap();
    let mut zip = zip::ZipArchive::new(file).unwrap();
    let mut text = String::new();
    std::io::Read::read_to_string(&mut zip.by_name("modelDescription.xml").unwrap(), &mut text)
        .unwrap();
    text
}

/// Every interface of every FMU in `dir` (not recursive).
fn cases_in(dir: &Path, cases: &mut Vec<Case>) {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "fmu"))
        .collect();
    paths.sort();
    for path in paths {
        let xml = description_xml(&path);
        let tool = attribute(&xml, "generationTool").unwrap_or_default();
        let tool = tool
            .replace("OpenModelica Compiler OpenModelica", "OpenModelica")
            .replace("Reference FMUs (development build)", "Reference FMUs");
        let model = path.file_stem().unwrap().to_string_lossy().into_owned();
        let version = attribute(&xml, "fmiVersion").unwrap_or_default();
        for (tag, interface) in [
            ("<ModelExchange", Interface::ModelExchange),
            ("<CoSimulation", Interface::CoSimulation),
        ] {
            if xml.contains(tag) {
                cases.push(Case {
                    tool: tool.clone(),
                    model: model.clone(),
                    version: version.clone(),
                    interface,
                    path: path.clone(),
                });
            }
        }
    }
}

/// A CSV of numbers with a header (names may be quoted).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let mut header = Vec::new();
    let mut cell = String::new();
    let mut quoted = false;
    for c in lines.next().unwrap_or("").chars() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => header.push(std::mem::take(&mut cell)),
            c => cell.push(c),
        }
    }
    header.push(cell);
    let rows = lines
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// A library this machine lacks, from a loader's message (`libX.so.N: cannot open shared
/// object file`).
fn missing_runtime(message: &str) -> Option<String> {
    let at = message.find(": cannot open shared object file")?;
    let name = message[..at].rsplit([' ', ':', '/']).next()?;
    name.contains(".so").then(|| name.to_string())
}

/// Why an FMU cannot be compared here (not a failure of calib), from its description.
fn left_out(xml: &str) -> Option<String> {
    if xml.contains("<Dimension") {
        return Some("array variables, which calib does not support yet".into());
    }
    None
}

/// Why a failure to load an FMU is no failure of calib: a runtime this machine lacks, or no
/// binary for it.
fn not_here(message: &str) -> Option<String> {
    if let Some(lib) = missing_runtime(message) {
        return Some(format!("needs a runtime this machine lacks: {lib}"));
    }
    if message.contains("undefined symbol: _Py") {
        return Some(
            "needs a runtime this machine lacks: the Python interpreter in the process \
             that loads it (PythonFMU3)"
                .into(),
        );
    }
    if message.contains("no binary for this platform") {
        return Some("no binary for this platform (linux64)".into());
    }
    None
}

/// Outputs that are no function of the model: the tool's own measure of its run time.
const UNCOMPARABLE: [&str; 1] = ["CPUtime"];

fn run(case: &Case, scratch: &Path) -> Outcome {
    let _alone = crate::one_real_tool_fmu_at_a_time();
    if let Some(why) = left_out(&description_xml(&case.path)) {
        return Outcome::Left(why);
    }
    let model = match fmu::open_local(&case.path, Some(case.interface)) {
        Ok(m) => m,
        Err(e) => return Outcome::Failed(format!("open: {e}")),
    };
    let description = model.description();
    let stop = description.default_stop_time.unwrap_or(1.0);
    let step = stop / 500.0;
    let grid: Vec<f64> = (0..=500).map(|i| i as f64 * step).collect();
    let info = model.info();
    let names: Vec<String> = info.outputs.iter().map(|o| o.name.clone()).collect();
    let outputs: Vec<usize> = (0..names.len()).collect();
    let calib = match model.simulate(&Run::new(
        &info.default_vector(),
        &grid,
        &outputs,
        &options(),
    )) {
        Ok(t) => t,
        Err(e) => {
            let message = e.to_string();
            return match not_here(&message) {
                Some(why) => Outcome::Left(why),
                None => Outcome::Failed(message),
            };
        }
    };
    let csv = scratch.join(format!(
        "{}-{}-{}.csv",
        case.model,
        case.version,
        case.interface.name().replace(' ', "-")
    ));
    let fmpy = std::process::Command::new("python3")
        .arg(repo().join("tests/python/fmpy_simulate.py"))
        .arg(&case.path)
        .arg(match case.interface {
            Interface::ModelExchange => "me",
            Interface::CoSimulation => "cs",
        })
        .arg(stop.to_string())
        .arg(step.to_string())
        .arg(ME_RTOL.to_string())
        .arg(&csv)
        .args(&names)
        .output()
        .expect("python3 runs");
    if !fmpy.status.success() {
        let why = String::from_utf8_lossy(&fmpy.stderr);
        let last = why.trim().lines().last().unwrap_or("").to_string();
        return Outcome::Left(format!("FMPy fails on it too: {last}"));
    }
    let (header, rows) = read_csv(&csv);
    // FMPy's rows at the grid's times (it may leave one out where a time event meets it).
    let at: Vec<(usize, &Vec<f64>)> = rows
        .iter()
        .filter_map(|r| {
            let i = (r[0] / step).round() as usize;
            (i < grid.len() && (grid[i] - r[0]).abs() <= 1e-9 * stop).then_some((i, r))
        })
        .collect();
    // FMPy stops recording when the FMU asks to terminate (calib holds the outputs).
    assert!(at.len() > 1, "{}: FMPy gave {} rows", case.model, at.len());
    let mut worst = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let Some(col) = header.iter().position(|h| h == name) else {
            continue;
        };
        if UNCOMPARABLE.contains(&name.as_str()) {
            continue;
        }
        let theirs: Vec<f64> = at.iter().map(|(_, r)| r[col]).collect();
        let (lo, hi) = theirs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
        let size = theirs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let scale = (hi - lo).max(1e-6 * (1.0 + size));
        let diff = at
            .iter()
            .map(|(i, r)| (r[col] - calib.values[k][*i]).abs())
            .fold(0.0, f64::max);
        worst.push((name.clone(), diff / scale));
    }
    Outcome::Compared(worst, at.len())
}

#[test]
fn every_output_of_real_tool_and_reference_fmus_agrees_with_fmpy() {
    let mut cases = Vec::new();
    if let Some(dir) = real_tool_fmus() {
        for sub in ["gemseo-fmu", "modestpy/simple2R1C", "aixcalibuha"] {
            cases_in(&dir.join(sub), &mut cases);
        }
    }
    if let Some(dir) = reference_fmus() {
        for version in ["fmi2", "fmi3"] {
            cases_in(&dir.join(version), &mut cases);
        }
    }
    if cases.is_empty() {
        return;
    }
    let fmpy = std::process::Command::new("python3")
        .args(["-c", "import fmpy"])
        .output();
    if !fmpy.is_ok_and(|o| o.status.success()) {
        skip("FMPy, the second opinion (`pip install fmpy==0.3.32`), is not installed");
        return;
    }
    let scratch = tempfile::tempdir().unwrap();
    let mut table = String::from(
        "| tool | model | FMI | interface | outputs × times | max |calib − FMPy| / range | worst output |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let mut failures = Vec::new();
    let (mut compared, mut left) = (0, Vec::new());
    for case in &cases {
        let outcome = run(case, scratch.path());
        let interface = match case.interface {
            Interface::ModelExchange => "ME",
            Interface::CoSimulation => "CS",
        };
        let row = match &outcome {
            Outcome::Compared(worst, times) => {
                let (name, e) =
                    worst
                        .iter()
                        .cloned()
                        .fold((String::new(), 0.0), |a, b| if b.1 > a.1 { b } else { a });
                let bound = match case.interface {
                    Interface::ModelExchange => ME_AGREEMENT,
                    Interface::CoSimulation => CS_AGREEMENT,
                };
                if e > bound {
                    failures.push(format!(
                        "{} {} {interface}: {name} differs by {e:.2e} of its range (allowed {bound:e})",
                        case.model, case.version
                    ));
                }
                compared += 1;
                format!("{} × {times} | {:.1e} | {name}", worst.len(), e)
            }
            Outcome::Left(why) => {
                left.push((case.model.clone(), interface, why.clone()));
                format!("– | left out: {why} |")
            }
            Outcome::Failed(why) => {
                failures.push(format!(
                    "{} {} {interface}: calib failed: {why}",
                    case.model, case.version
                ));
                format!("– | calib failed: {why} |")
            }
        };
        table.push_str(&format!(
            "| {} | {} | {} | {interface} | {row} |\n",
            case.tool, case.model, case.version
        ));
    }
    let mut out = std::io::stderr();
    writeln!(out, "{table}").unwrap();
    // Only the documented cases are left out, each for its reason, and every other is compared
    // (where every FMU is gathered: under CI they must be).
    for (model, interface, why) in &left {
        let expected = LEFT_OUT
            .iter()
            .any(|(m, i, reason)| m == model && i == interface && why.contains(reason));
        if !expected {
            failures.push(format!(
                "{model} {interface} left out, not documented so: {why}"
            ));
        }
    }
    if real_tool_fmus().is_some() && reference_fmus().is_some() {
        assert_eq!(left.len(), LEFT_OUT.len(), "left out: {left:?}\n{table}");
        assert_eq!(compared, COMPARED, "cases compared\n{table}");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The FMU of `tests/lazy_fmu/`, built with the C compiler and zipped into `dir`.
fn lazy_fmu(dir: &Path) -> Option<PathBuf> {
    let src = repo().join("tests/lazy_fmu");
    let so = dir.join("Lazy.so");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let built = std::process::Command::new(&cc)
        .args(["-shared", "-fPIC", "-O1", "-o"])
        .arg(&so)
        .arg(src.join("lazy.c"))
        .status();
    if !built.is_ok_and(|s| s.success()) {
        skip(&format!("no C compiler (`{cc}`) to build the lazy FMU"));
        return None;
    }
    let path = dir.join("Lazy.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let options = zip::write::SimpleFileOptions::default();
    zip.start_file("modelDescription.xml", options).unwrap();
    zip.write_all(&std::fs::read(src.join("lazy.xml")).unwrap())
        .unwrap();
    zip.start_file("binaries/linux64/Lazy.so", options).unwrap();
    zip.write_all(&std::fs::read(&so).unwrap()).unwrap();
    zip.finish().unwrap();
    Some(path)
}

/// The lazy FMU's temperature and heater in closed form: rising at 1/s from 0.05 to 1
/// (t = 0.95), then falling at 1.5/s to 0.5 and rising again, a period of 5/6 s.
fn thermostat(t: f64) -> (f64, f64) {
    if t < 0.95 {
        return (0.05 + t, 1.0);
    }
    let s = (t - 0.95) % (5.0 / 6.0);
    if s < 1.0 / 3.0 {
        (1.0 - 1.5 * s, 0.0)
    } else {
        (0.5 + (s - 1.0 / 3.0), 1.0)
    }
}

/// Series by name.
type Named = Vec<(String, Vec<f64>)>;

/// The lazy FMU through Model Exchange with `max_switches`: grid, outputs by name.
fn simulate_lazy(max_switches: f64) -> Option<(Vec<f64>, Named)> {
    let dir = tempfile::tempdir().unwrap();
    let path = lazy_fmu(dir.path())?;
    let model = fmu::open_local(&path, Some(Interface::ModelExchange)).unwrap();
    let info = model.info();
    let mut params = info.default_vector();
    params[info.parameter_index("max_switches").unwrap()] = max_switches;
    let grid: Vec<f64> = (0..=40).map(|i| i as f64 * 0.1).collect();
    let names = [
        "T",
        "y",
        "power",
        "steps",
        "requested",
        "handled",
        "backwards",
    ];
    let outputs: Vec<usize> = names
        .iter()
        .map(|n| info.output_index(n).unwrap())
        .collect();
    let t = model
        .simulate(&Run::new(&params, &grid, &outputs, &options()))
        .unwrap();
    let named = names.iter().map(|n| n.to_string()).zip(t.values).collect();
    Some((grid, named))
}

#[test]
fn a_model_exchange_fmu_that_computes_only_when_asked_runs_to_its_closed_form() {
    let Some((grid, values)) = simulate_lazy(1000.0) else {
        return;
    };
    let series = |name: &str| &values.iter().find(|(n, _)| n == name).unwrap().1;
    for (i, &t) in grid.iter().enumerate() {
        let (temperature, power) = thermostat(t);
        // The heater switches at each crossing: the FMU decides on what it computed last,
        // so it must have computed at the event's time and states.
        assert!(
            (series("T")[i] - temperature).abs() < 1e-6,
            "T({t}) = {} vs {temperature}",
            series("T")[i]
        );
        assert_eq!(series("power")[i], power, "heater at {t}");
        // y is computed with the derivatives only: read after them, at the output's time.
        assert!(
            (series("y")[i] - 2.0 * temperature).abs() < 2e-6,
            "y({t}) = {} vs {}",
            series("y")[i],
            2.0 * temperature
        );
    }
    let last = |name: &str| *series(name).last().unwrap();
    // Every accepted step is completed, in time order; the step events the FMU asks for
    // are handled.
    assert!(last("steps") >= 5.0, "{} steps", last("steps"));
    assert!(last("requested") >= 1.0);
    assert_eq!(last("handled"), last("requested"));
    assert_eq!(last("backwards"), 0.0);
}

#[test]
fn a_model_exchange_fmu_that_asks_to_terminate_holds_its_outputs() {
    let Some((grid, values)) = simulate_lazy(5.0) else {
        return;
    };
    let series = |name: &str| &values.iter().find(|(n, _)| n == name).unwrap().1;
    // The fifth switch, the heater going off at T = 1, is at 0.95 + 2·5/6 s.
    let end = 0.95 + 2.0 * 5.0 / 6.0;
    for (i, &t) in grid.iter().enumerate() {
        let (temperature, power) = if t < end { thermostat(t) } else { (1.0, 0.0) };
        assert!(
            (series("T")[i] - temperature).abs() < 1e-6,
            "T({t}) = {} vs {temperature}",
            series("T")[i]
        );
        assert_eq!(series("power")[i], power, "heater at {t}");
    }
}
