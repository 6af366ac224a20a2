//! PEST template files (`ptf`): where parameter values go in a model's input files.
//!
//! The first line is `ptf <marker>`; the rest is the input file, in which each parameter
//! space `#name    #` (between two markers, on one line) is replaced by the parameter's
//! value. The space's width, markers included, is the width the value is written in: as
//! many significant digits as fit, right-justified, with a decimal point (`point`, PEST's
//! default) so that a Fortran free-format read takes it as a real. A leading zero is dropped
//! (`.01235`) and an exponent is written as short as it reads (`1.2346E-7`) when that gains a
//! digit. A value that does not fit in its space is an error naming the file, the line and
//! the column.

use super::instructions::{header_marker, located, within, PestFileError};
use std::collections::BTreeMap;

/// Largest template file read [bytes].
pub const MAX_TEMPLATE_BYTES: usize = 16 << 20;

/// One parameter space: its line and column (1-based) in the template, its width (markers
/// included), and the parameter's name.
#[derive(Debug, Clone, PartialEq)]
struct Space {
    line: usize,
    column: usize,
    width: usize,
    name: String,
}

/// A parsed template: the input file's text and its parameter spaces.
#[derive(Debug, Clone)]
pub struct Template {
    file: String,
    /// The input file's lines, each as pieces of text and spaces, in order.
    lines: Vec<Vec<Piece>>,
    spaces: Vec<Space>,
}

#[derive(Debug, Clone)]
enum Piece {
    Text(String),
    Space(usize),
}

impl Template {
    /// Parse the template file `text`, named `file` in errors.
    pub fn parse(text: &str, file: &str) -> Result<Template, PestFileError> {
        let error = located(file);
        within(text, MAX_TEMPLATE_BYTES, "a template file", file)?;
        let mut rows = text.split_inclusive('\n').enumerate();
        let (_, header) = rows
            .next()
            .ok_or_else(|| error(1, 1, "empty: the first line must be `ptf <marker>`".into()))?;
        let marker = header_marker(header.trim_end(), "ptf").map_err(|m| error(1, 1, m))?;
        let (mut lines, mut spaces) = (Vec::new(), Vec::new());
        for (index, row) in rows {
            let number = index + 1;
            let mut pieces = Vec::new();
            let mut rest = row;
            let mut column = 1;
            while let Some(open) = rest.find(marker) {
                let after = &rest[open + marker.len_utf8()..];
                let close = after.find(marker).ok_or_else(|| {
                    error(
                        number,
                        column + rest[..open].chars().count(),
                        format!("parameter space opened by `{marker}` and not closed on its line"),
                    )
                })?;
                let name = after[..close].trim();
                let at = column + rest[..open].chars().count();
                if name.is_empty() {
                    return Err(error(number, at, "a parameter space without a name".into()));
                }
                let width = after[..close].chars().count() + 2;
                pieces.push(Piece::Text(rest[..open].to_string()));
                pieces.push(Piece::Space(spaces.len()));
                spaces.push(Space {
                    line: number,
                    column: at,
                    width,
                    name: name.to_string(),
                });
                let used = open + marker.len_utf8() + close + marker.len_utf8();
                column += rest[..used].chars().count();
                rest = &rest[used..];
            }
            pieces.push(Piece::Text(rest.to_string()));
            lines.push(pieces);
        }
        Ok(Template {
            file: file.to_string(),
            lines,
            spaces,
        })
    }

    /// The parameters the template names, each once, in order of first appearance.
    pub fn parameters(&self) -> Vec<&str> {
        let mut seen = Vec::new();
        for s in &self.spaces {
            if !seen.contains(&s.name.as_str()) {
                seen.push(s.name.as_str());
            }
        }
        seen
    }

    /// The input file with each space holding its parameter's value from `values` (names
    /// compared as PEST does, without regard to case).
    pub fn write(&self, values: &BTreeMap<String, f64>) -> Result<String, PestFileError> {
        let lower: BTreeMap<String, f64> = values
            .iter()
            .map(|(k, v)| (k.to_ascii_lowercase(), *v))
            .collect();
        let mut out = String::new();
        for pieces in &self.lines {
            for piece in pieces {
                match piece {
                    Piece::Text(text) => out.push_str(text),
                    Piece::Space(k) => {
                        let space = &self.spaces[*k];
                        let error = |message: String| PestFileError {
                            file: self.file.clone(),
                            line: space.line,
                            column: space.column,
                            message,
                        };
                        let value = lower
                            .get(&space.name.to_ascii_lowercase())
                            .ok_or_else(|| error(format!("no value for `{}`", space.name)))?;
                        let text = fit(*value, space.width).ok_or_else(|| {
                            error(format!(
                                "{value} does not fit the {} characters of `{}`'s space",
                                space.width, space.name
                            ))
                        })?;
                        out.push_str(&format!("{text:>width$}", width = space.width));
                    }
                }
            }
        }
        Ok(out)
    }
}

/// `value` in at most `width` characters, with a decimal point, as close to it as that
/// width allows; `None` when not even one significant digit fits.
pub fn fit(value: f64, width: usize) -> Option<String> {
    if !value.is_finite() {
        return None;
    }
    let mut best: Option<(f64, String)> = None;
    for precision in 0..=17usize {
        for text in [fixed(value, precision), scientific(value, precision)] {
            let text = shortened(text);
            if text.len() > width || !text.contains('.') {
                continue;
            }
            let Ok(read) = text.parse::<f64>() else {
                continue;
            };
            let error = (read - value).abs();
            let better = match &best {
                None => true,
                Some((e, t)) => error < *e || (error == *e && text.len() < t.len()),
            };
            if better {
                best = Some((error, text));
            }
        }
    }
    best.map(|(_, text)| text)
}

fn fixed(value: f64, precision: usize) -> String {
    let text = format!("{value:.precision$}");
    if text.contains('.') {
        text
    } else {
        text + "."
    }
}

/// `d.dddE±x` with the exponent as short as it reads.
fn scientific(value: f64, precision: usize) -> String {
    let text = format!("{value:.precision$E}");
    let (mantissa, exponent) = text.split_once('E').expect("an exponent");
    let mantissa = if mantissa.contains('.') {
        mantissa.to_string()
    } else {
        format!("{mantissa}.")
    };
    format!("{mantissa}E{exponent}")
}

/// Without the leading zero before a decimal point (`0.5` → `.5`, `-0.5` → `-.5`).
fn shortened(text: String) -> String {
    if let Some(rest) = text.strip_prefix("0.") {
        format!(".{rest}")
    } else if let Some(rest) = text.strip_prefix("-0.") {
        format!("-.{rest}")
    } else {
        text
    }
}
