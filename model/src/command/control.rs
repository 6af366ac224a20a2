//! PEST control files (`.pst`): a model's parameters, its observations with their weights,
//! its command line and the template and instruction files of its input and output files.
//!
//! What is read: `* control data` (the counts, `PRECIS`, `DPOINT` and `NOPTMAX`),
//! `* parameter data` (with tied parameters), `* observation data`, `* model command line`
//! and `* model input/output`. Every other section (parameter and observation groups,
//! singular value decomposition, LSQR, prior information, regularisation, PEST++ options) is
//! named in [`ControlFile::ignored`] and does nothing. A parameter's value in a template is
//! `value × scale + offset`, as PEST writes it; the objective is PEST's phi, Σ (w·(obs − sim))².

use super::instructions::{located, within, PestFileError};
use std::collections::BTreeMap;

/// Largest control file read [bytes].
pub const MAX_CONTROL_BYTES: usize = 64 << 20;

/// How PEST treats a parameter.
#[derive(Debug, Clone, PartialEq)]
pub enum Transform {
    /// Estimated as it is.
    None,
    /// Estimated as its logarithm (calib: a log10 scale).
    Log,
    /// Held at its initial value.
    Fixed,
    /// Held at its initial ratio to the parameter named.
    Tied(String),
}

/// A parameter of `* parameter data`.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    pub name: String,
    pub transform: Transform,
    pub initial: f64,
    pub lower: f64,
    pub upper: f64,
    pub group: String,
    pub scale: f64,
    pub offset: f64,
}

/// An observation of `* observation data`.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    pub name: String,
    pub value: f64,
    pub weight: f64,
    pub group: String,
}

/// A parsed control file.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlFile {
    pub parameters: Vec<Parameter>,
    pub observations: Vec<Observation>,
    /// The model's command line.
    pub command: String,
    /// (template, model input file) pairs.
    pub templates: FilePairs,
    /// (instruction file, model output file) pairs.
    pub instructions: FilePairs,
    /// PEST's iteration limit: 0 runs the model once and reports phi.
    pub noptmax: i64,
    /// Sections present but not read, by their headings.
    pub ignored: Vec<String>,
}

impl ControlFile {
    /// Parse the control file `text`, named `file` in errors.
    pub fn parse(text: &str, file: &str) -> Result<ControlFile, PestFileError> {
        within(text, MAX_CONTROL_BYTES, "a control file", file)?;
        let error = located(file);
        let lines: Vec<&str> = text.lines().collect();
        if !lines
            .first()
            .is_some_and(|l| l.trim().eq_ignore_ascii_case("pcf"))
        {
            return Err(error(
                1,
                1,
                "the first line of a control file is `pcf`".into(),
            ));
        }
        let sections = sections(&lines);
        let section = |name: &str| sections.iter().find(|(n, _, _)| n == name);
        let body = |name: &str| -> Result<(usize, &[&str]), PestFileError> {
            section(name)
                .map(|(_, start, rows)| (*start, *rows))
                .ok_or_else(|| error(1, 1, format!("no `* {name}` section")))
        };
        let (start, control) = body("control data")?;
        let control = Control::read(control, start, &error)?;
        let (start, rows) = body("parameter data")?;
        let parameters = read_parameters(rows, start, control.parameters, &error)?;
        let (start, rows) = body("observation data")?;
        let observations = read_observations(rows, start, control.observations, &error)?;
        let (start, rows) = body("model command line")?;
        let command = rows
            .iter()
            .map(|r| r.trim())
            .find(|r| !r.is_empty())
            .ok_or_else(|| error(start, 1, "no model command line".into()))?
            .to_string();
        let (start, rows) = body("model input/output")?;
        let (templates, instructions) = read_files(rows, start, &control, &error)?;
        let read = [
            "control data",
            "parameter data",
            "observation data",
            "model command line",
            "model input/output",
        ];
        let ignored = sections
            .iter()
            .map(|(n, _, _)| n.clone())
            .filter(|n| !read.contains(&n.as_str()))
            .collect();
        Ok(ControlFile {
            parameters,
            observations,
            command,
            templates,
            instructions,
            noptmax: control.noptmax,
            ignored,
        })
    }

    /// The value each parameter takes in the templates, its estimated ones from `values`
    /// (by name; the others at their initial values), tied ones at their initial ratio to
    /// their parent's value, each then scaled and offset as PEST does.
    pub fn model_values(&self, values: &BTreeMap<String, f64>) -> BTreeMap<String, f64> {
        let value = |p: &Parameter| match p.transform {
            Transform::None | Transform::Log => *values.get(&p.name).unwrap_or(&p.initial),
            _ => p.initial,
        };
        let mut out = BTreeMap::new();
        for p in &self.parameters {
            let v = match &p.transform {
                Transform::Tied(parent) => {
                    let parent = self.parameters.iter().find(|q| &q.name == parent);
                    parent.map_or(p.initial, |q| p.initial / q.initial * value(q))
                }
                _ => value(p),
            };
            out.insert(p.name.clone(), v * p.scale + p.offset);
        }
        out
    }

    /// PEST's phi: Σ (weight × (observed − simulated))² over the observations, `simulated`
    /// by name (lower case, as PEST compares names); an observation without a simulated
    /// value is an error naming it.
    pub fn phi(&self, simulated: &BTreeMap<String, f64>) -> Result<f64, String> {
        let mut phi = 0.0;
        for o in &self.observations {
            let sim = simulated
                .get(&o.name)
                .ok_or_else(|| format!("observation `{}` was not read", o.name))?;
            phi += (o.weight * (o.value - sim)).powi(2);
        }
        Ok(phi)
    }
}

/// The sections of a control file: each heading (`* name`, lower case) with the line number
/// of its first row and its rows (up to the next heading; `++` option lines end a section).
fn sections<'a>(lines: &'a [&'a str]) -> Vec<(String, usize, &'a [&'a str])> {
    let headings: Vec<(usize, String)> = lines
        .iter()
        .enumerate()
        .filter_map(|(i, l)| {
            let l = l.trim_start();
            if let Some(name) = l.strip_prefix('*') {
                Some((i, name.trim().to_ascii_lowercase()))
            } else {
                l.starts_with("++")
                    .then(|| (i, "++ pest++ options".to_string()))
            }
        })
        .collect();
    let mut out: Vec<(String, usize, &[&str])> = Vec::new();
    for (k, (i, name)) in headings.iter().enumerate() {
        let end = headings.get(k + 1).map_or(lines.len(), |(j, _)| *j);
        if name.starts_with("++") {
            if out.last().is_none_or(|(n, _, _)| !n.starts_with("++")) {
                out.push((name.clone(), i + 1, &lines[*i..end]));
            }
            continue;
        }
        out.push((name.clone(), i + 2, &lines[i + 1..end]));
    }
    out
}

/// What `* control data` holds that calib reads.
struct Control {
    parameters: usize,
    observations: usize,
    templates: usize,
    instructions: usize,
    noptmax: i64,
}

impl Control {
    fn read(
        rows: &[&str],
        start: usize,
        error: &impl Fn(usize, usize, String) -> PestFileError,
    ) -> Result<Control, PestFileError> {
        let words = |k: usize| -> Result<Vec<&str>, PestFileError> {
            rows.get(k)
                .map(|r| r.split_whitespace().collect())
                .ok_or_else(|| error(start + k, 1, "the control data end early".into()))
        };
        let count = |k: usize, i: usize, what: &str| -> Result<usize, PestFileError> {
            let row = words(k)?;
            row.get(i)
                .and_then(|w| w.parse().ok())
                .ok_or_else(|| error(start + k, 1, format!("{what}: a whole number expected")))
        };
        let noptmax = words(6)?
            .first()
            .and_then(|w| w.parse().ok())
            .ok_or_else(|| error(start + 6, 1, "NOPTMAX: a whole number expected".into()))?;
        Ok(Control {
            parameters: count(1, 0, "NPAR")?,
            observations: count(1, 1, "NOBS")?,
            templates: count(2, 0, "NTPLFLE")?,
            instructions: count(2, 1, "NINSFLE")?,
            noptmax,
        })
    }
}

/// The error of a section (from line `start`) that gives `given` `what` where the control
/// data announced `count`.
fn announced(
    count: usize,
    given: usize,
    what: &str,
    start: usize,
    error: &impl Fn(usize, usize, String) -> PestFileError,
) -> PestFileError {
    error(start, 1, format!("{count} {what} announced, {given} given"))
}

/// A number as PEST reads one (Fortran `D` exponents too).
fn number(word: &str) -> Option<f64> {
    word.replace(['d', 'D'], "e")
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
}

/// `* parameter data`: `count` parameters, then a `name parent` line per tied one.
fn read_parameters(
    rows: &[&str],
    start: usize,
    count: usize,
    error: &impl Fn(usize, usize, String) -> PestFileError,
) -> Result<Vec<Parameter>, PestFileError> {
    let rows: Vec<(usize, Vec<&str>)> = rows
        .iter()
        .enumerate()
        .map(|(k, r)| (start + k, r.split_whitespace().collect::<Vec<_>>()))
        .filter(|(_, w)| !w.is_empty())
        .collect();
    if rows.len() < count {
        return Err(announced(count, rows.len(), "parameters", start, error));
    }
    let mut parameters = rows[..count]
        .iter()
        .map(|(line, w)| parameter(*line, w, error))
        .collect::<Result<Vec<_>, _>>()?;
    for (line, w) in &rows[count..] {
        let (Some(child), Some(parent)) = (w.first(), w.get(1)) else {
            continue;
        };
        let (child, parent) = (child.to_ascii_lowercase(), parent.to_ascii_lowercase());
        if !parameters.iter().any(|p| p.name == parent) {
            return Err(error(
                *line,
                1,
                format!("{child} is tied to `{parent}`, no parameter"),
            ));
        }
        match parameters.iter_mut().find(|p| p.name == child) {
            Some(p) if p.transform == Transform::Tied(String::new()) => {
                p.transform = Transform::Tied(parent)
            }
            _ => return Err(error(*line, 1, format!("`{child}` is no tied parameter"))),
        }
    }
    if let Some(p) = parameters
        .iter()
        .find(|p| p.transform == Transform::Tied(String::new()))
    {
        return Err(error(
            start,
            1,
            format!("{} is tied to no parameter", p.name),
        ));
    }
    Ok(parameters)
}

/// One row of `* parameter data` (its words `w`, on line `line`).
fn parameter(
    line: usize,
    w: &[&str],
    error: &impl Fn(usize, usize, String) -> PestFileError,
) -> Result<Parameter, PestFileError> {
    if w.len() < 9 {
        return Err(error(
            line,
            1,
            "a parameter takes PARNME PARTRANS PARCHGLIM PARVAL1 PARLBND PARUBND PARGP SCALE \
             OFFSET"
                .into(),
        ));
    }
    let value = |i: usize, what: &str| {
        number(w[i]).ok_or_else(|| {
            error(
                line,
                1,
                format!("{}: {what} `{}` is not a number", w[0], w[i]),
            )
        })
    };
    let transform = match w[1].to_ascii_lowercase().as_str() {
        "none" => Transform::None,
        "log" => Transform::Log,
        "fixed" => Transform::Fixed,
        "tied" => Transform::Tied(String::new()),
        other => {
            return Err(error(
                line,
                1,
                format!(
                    "{}: PARTRANS `{other}` is none of none, log, fixed, tied",
                    w[0]
                ),
            ))
        }
    };
    Ok(Parameter {
        name: w[0].to_ascii_lowercase(),
        transform,
        initial: value(3, "PARVAL1")?,
        lower: value(4, "PARLBND")?,
        upper: value(5, "PARUBND")?,
        group: w[6].to_ascii_lowercase(),
        scale: value(7, "SCALE")?,
        offset: value(8, "OFFSET")?,
    })
}

/// `* observation data`: `count` observations.
fn read_observations(
    rows: &[&str],
    start: usize,
    count: usize,
    error: &impl Fn(usize, usize, String) -> PestFileError,
) -> Result<Vec<Observation>, PestFileError> {
    let mut observations = Vec::with_capacity(count);
    for (k, row) in rows.iter().enumerate() {
        let w: Vec<&str> = row.split_whitespace().collect();
        if w.is_empty() {
            continue;
        }
        let line = start + k;
        let value = |i: usize, what: &str| {
            w.get(i)
                .and_then(|v| number(v))
                .ok_or_else(|| error(line, 1, format!("{}: {what} is not a number", w[0])))
        };
        observations.push(Observation {
            name: w[0].to_ascii_lowercase(),
            value: value(1, "OBSVAL")?,
            weight: value(2, "WEIGHT")?,
            group: w.get(3).map(|g| g.to_ascii_lowercase()).unwrap_or_default(),
        });
    }
    if observations.len() != count {
        return Err(announced(
            count,
            observations.len(),
            "observations",
            start,
            error,
        ));
    }
    Ok(observations)
}

/// (PEST file, model file) pairs.
type FilePairs = Vec<(String, String)>;

/// `* model input/output`: the templates, then the instruction files, as many as announced.
fn read_files(
    rows: &[&str],
    start: usize,
    control: &Control,
    error: &impl Fn(usize, usize, String) -> PestFileError,
) -> Result<(FilePairs, FilePairs), PestFileError> {
    let pairs: Vec<(usize, (String, String))> = rows
        .iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let mut w = r.split_whitespace();
            Some((start + k, (w.next()?.to_string(), w.next()?.to_string())))
        })
        .collect();
    let wanted = control.templates + control.instructions;
    if pairs.len() != wanted {
        return Err(announced(
            wanted,
            pairs.len(),
            "template and instruction files",
            start,
            error,
        ));
    }
    let (templates, instructions) = pairs.split_at(control.templates);
    Ok((
        templates.iter().map(|(_, p)| p.clone()).collect(),
        instructions.iter().map(|(_, p)| p.clone()).collect(),
    ))
}
