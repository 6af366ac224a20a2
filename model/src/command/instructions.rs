//! PEST instruction files (`pif`): where each observation is read in a model's output file.
//!
//! The first line is `pif <marker>`. Each instruction line begins with a line advance `lN`
//! or a primary marker (`&` continues the line before), then any of:
//! - `lN`: down N lines, the cursor before the line's first character;
//! - a primary marker `#text#` (first on its line, or after `lN`): the first line holding
//!   the text, searched from the next line (from the line advanced to after `lN`), the
//!   cursor on the text's last character;
//! - a secondary marker `#text#` (any later item): the text searched on the current line
//!   from the cursor on;
//! - `w`: past the next run of blanks, the cursor on the last blank;
//! - `tN`: the cursor on column N;
//! - `!obs!`: the number starting at the first non-blank character after the cursor, up to
//!   a blank, a comma or the line's end (as Fortran's free-format read separates values);
//! - `[obs]c1:c2`: the number in columns c1 to c2 (1-based, inclusive);
//! - `(obs)c1:c2`: the number whose first non-blank character is in columns c1 to c2, read
//!   as a non-fixed one from there;
//! - `dum` as an observation's name reads a number and keeps nothing.
//!
//! Numbers are read as Fortran reads them: an optional sign, digits with a decimal point,
//! an exponent with `E` or `D`. Every mistake, in the instruction file or in reading the
//! output, names the file, the line and the column.

use std::fmt;

/// Largest instruction file read [bytes].
pub const MAX_INSTRUCTION_BYTES: usize = 16 << 20;
/// Most observations one instruction file reads.
pub const MAX_OBSERVATIONS: usize = 1 << 20;

/// A mistake in a PEST file (a template, an instruction or a control file), or in reading
/// an output file with an instruction file: the file, the line and the column (1-based)
/// where it was found.
#[derive(Debug, Clone, PartialEq)]
pub struct PestFileError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
}

impl fmt::Display for PestFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}",
            self.file, self.line, self.column, self.message
        )
    }
}

impl std::error::Error for PestFileError {}

/// The error of file `file` at a line and column.
pub(super) fn located(file: &str) -> impl Fn(usize, usize, String) -> PestFileError + '_ {
    move |line, column, message| PestFileError {
        file: file.to_string(),
        line,
        column,
        message,
    }
}

/// Refuse `text`, the `kind` file `file`, when it is larger than `limit` bytes.
pub(super) fn within(
    text: &str,
    limit: usize,
    kind: &str,
    file: &str,
) -> Result<(), PestFileError> {
    if text.len() > limit {
        return Err(located(file)(
            1,
            1,
            format!(
                "{} bytes, more than the {limit} {kind} may hold",
                text.len()
            ),
        ));
    }
    Ok(())
}

/// One instruction.
#[derive(Debug, Clone, PartialEq)]
enum Item {
    Advance(usize),
    Primary(String),
    Secondary(String),
    Whitespace,
    Tab(usize),
    /// An observation (`None`: a dummy) and how it is read.
    Read(Option<String>, Reading),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Reading {
    NonFixed,
    Fixed(usize, usize),
    SemiFixed(usize, usize),
}

/// An instruction line: its items, each with its column in the instruction file.
#[derive(Debug, Clone)]
struct Line {
    number: usize,
    items: Vec<(usize, Item)>,
}

/// A parsed instruction file.
#[derive(Debug, Clone)]
pub struct Instructions {
    file: String,
    lines: Vec<Line>,
    observations: Vec<String>,
}

impl Instructions {
    /// Parse the instruction file `text`, named `file` in errors.
    pub fn parse(text: &str, file: &str) -> Result<Instructions, PestFileError> {
        let error = located(file);
        within(text, MAX_INSTRUCTION_BYTES, "an instruction file", file)?;
        let mut rows = text.lines().enumerate();
        let (_, header) = rows
            .next()
            .ok_or_else(|| error(1, 1, "empty: the first line must be `pif <marker>`".into()))?;
        let marker = header_marker(header, "pif").map_err(|m| error(1, 1, m))?;
        let mut lines: Vec<Line> = Vec::new();
        let mut observations = Vec::new();
        for (index, row) in rows {
            let number = index + 1;
            let Some((continued, items)) = line_items(row, marker, &mut observations)
                .map_err(|(column, m)| error(number, column, m))?
            else {
                continue;
            };
            match (continued, lines.last_mut()) {
                (true, Some(last)) => last.items.extend(items),
                (true, None) => return Err(error(number, 1, "`&` continues no line".into())),
                (false, _) => lines.push(Line { number, items }),
            }
        }
        Ok(Instructions {
            file: file.to_string(),
            lines,
            observations,
        })
    }

    /// The observations read, in order (dummies left out).
    pub fn observations(&self) -> &[String] {
        &self.observations
    }

    /// Read the observations from the output file `output` (named `file` in errors), in the
    /// order [`Instructions::observations`] gives.
    pub fn read(&self, output: &str, file: &str) -> Result<Vec<f64>, PestFileError> {
        let mut cursor = Cursor {
            rows: output.lines().map(str::as_bytes).collect(),
            current: None,
            at: 0,
        };
        let mut values = Vec::with_capacity(self.observations.len());
        for line in &self.lines {
            let mut advanced = false;
            for (column, item) in &line.items {
                let read = cursor
                    .apply(item, advanced)
                    .map_err(|message| PestFileError {
                        file: self.file.clone(),
                        line: line.number,
                        column: *column,
                        message: format!("{message} (reading {file})"),
                    })?;
                advanced = matches!(item, Item::Advance(_));
                if let (Some(value), Item::Read(Some(_), _)) = (read, item) {
                    values.push(value);
                }
            }
        }
        Ok(values)
    }
}

/// Where reading an output file stands: its lines, the current one, and the next character
/// to look at on it.
struct Cursor<'a> {
    rows: Vec<&'a [u8]>,
    current: Option<usize>,
    at: usize,
}

impl Cursor<'_> {
    /// Carry out `item` (`advanced`: it follows a line advance on its line); the number it
    /// read, if it reads one.
    fn apply(&mut self, item: &Item, advanced: bool) -> Result<Option<f64>, String> {
        match item {
            Item::Advance(n) => self.advance(*n)?,
            Item::Primary(text) => self.primary(text, advanced)?,
            Item::Secondary(text) => {
                let row = self.row()?;
                let i = find(row, text.as_bytes(), self.at).ok_or_else(|| {
                    format!(
                        "secondary marker `{text}` not found on output line {} after column {}",
                        self.line(),
                        self.at
                    )
                })?;
                self.at = i + text.len();
            }
            Item::Whitespace => self.whitespace()?,
            Item::Tab(n) => {
                let row = self.row()?;
                if *n > row.len() {
                    return Err(format!(
                        "output line {} has {} columns, fewer than {n}",
                        self.line(),
                        row.len()
                    ));
                }
                self.at = *n;
            }
            Item::Read(name, reading) => {
                let (value, end) = read_number(self.row()?, self.at, *reading).map_err(|m| {
                    format!(
                        "{}: {m} on output line {}",
                        name.as_deref().unwrap_or("dum"),
                        self.line()
                    )
                })?;
                self.at = end;
                return Ok(Some(value));
            }
        }
        Ok(None)
    }

    /// The current line's number (1-based).
    fn line(&self) -> usize {
        self.current.map_or(0, |c| c + 1)
    }

    fn row(&self) -> Result<&[u8], String> {
        self.current
            .and_then(|c| self.rows.get(c).copied())
            .ok_or_else(|| format!("the output ends after {} lines", self.rows.len()))
    }

    fn advance(&mut self, n: usize) -> Result<(), String> {
        let to = self.current.map_or(n - 1, |c| c + n);
        if to >= self.rows.len() {
            return Err(format!(
                "cannot advance {n} lines: the output ends after {} lines",
                self.rows.len()
            ));
        }
        self.current = Some(to);
        self.at = 0;
        Ok(())
    }

    /// The first line holding `text`, from the next line on (from the current one after a
    /// line advance).
    fn primary(&mut self, text: &str, advanced: bool) -> Result<(), String> {
        let from = match (advanced, self.current) {
            (true, Some(c)) => c,
            (_, Some(c)) => c + 1,
            (_, None) => 0,
        };
        let (row, end) = (from..self.rows.len())
            .find_map(|r| find(self.rows[r], text.as_bytes(), 0).map(|i| (r, i + text.len())))
            .ok_or_else(|| {
                format!(
                    "primary marker `{text}` not found from output line {} on",
                    from + 1
                )
            })?;
        self.current = Some(row);
        self.at = end;
        Ok(())
    }

    /// Past the next run of blanks.
    fn whitespace(&mut self) -> Result<(), String> {
        let row = self.row()?;
        let mut i = self.at;
        while i < row.len() && !blank(row[i]) {
            i += 1;
        }
        while i < row.len() && blank(row[i]) {
            i += 1;
        }
        if i >= row.len() {
            return Err(format!(
                "no blank followed by more on output line {} after column {}",
                self.line(),
                self.at
            ));
        }
        self.at = i;
        Ok(())
    }
}

/// A mistake on an instruction line: its column, and what is wrong.
type Located = (usize, String);

/// A line's items, each with its column.
type Items = Vec<(usize, Item)>;

/// The items of one instruction line with their columns, the observations it reads added
/// to `observations`, and whether it continues the line before (`&`); `None` for a blank line.
fn line_items(
    row: &str,
    marker: char,
    observations: &mut Vec<String>,
) -> Result<Option<(bool, Items)>, Located> {
    let tokens = tokens(row, marker)?;
    let Some((first_column, first)) = tokens.first() else {
        return Ok(None);
    };
    let continued = first == "&";
    let mut items: Vec<(usize, Item)> = Vec::with_capacity(tokens.len());
    for (column, token) in tokens.iter().skip(usize::from(continued)) {
        let after_advance = matches!(items.as_slice(), [(_, Item::Advance(_))]);
        let leading = !continued && (items.is_empty() || after_advance);
        let item = item(token, marker, leading).map_err(|m| (*column, m))?;
        if let Item::Read(Some(name), _) = &item {
            if observations.len() == MAX_OBSERVATIONS {
                return Err((
                    *column,
                    format!("more than the {MAX_OBSERVATIONS} observations a file may read"),
                ));
            }
            observations.push(name.clone());
        }
        items.push((*column, item));
    }
    if !continued
        && !matches!(
            items.first(),
            Some((_, Item::Advance(_) | Item::Primary(_)))
        )
    {
        return Err((
            *first_column,
            "an instruction line begins with a line advance `lN` or a primary marker".into(),
        ));
    }
    Ok(Some((continued, items)))
}

/// The marker character of a `pif #` or `ptf #` header.
pub(super) fn header_marker(header: &str, kind: &str) -> Result<char, String> {
    let mut words = header.split_whitespace();
    let (Some(word), Some(marker), None) = (words.next(), words.next(), words.next()) else {
        return Err(format!(
            "the first line must be `{kind} <marker>`, not `{header}`"
        ));
    };
    let mut chars = marker.chars();
    match (word.eq_ignore_ascii_case(kind), chars.next(), chars.next()) {
        (true, Some(m), None) if !m.is_alphanumeric() && !"[]()!&".contains(m) => Ok(m),
        _ => Err(format!(
            "the first line must be `{kind} <marker>`, one character neither a letter, a \
             digit nor one of []()!&, not `{header}`"
        )),
    }
}

/// The items of one instruction line with their (1-based) columns: markers whole (blanks
/// inside kept), other items split at blanks.
fn tokens(row: &str, marker: char) -> Result<Vec<(usize, String)>, Located> {
    let chars: Vec<char> = row.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        if chars[i].is_whitespace() {
            i += 1;
            continue;
        }
        let start = i;
        if chars[i] == marker {
            let close = chars[i + 1..]
                .iter()
                .position(|c| *c == marker)
                .ok_or((start + 1, format!("marker `{marker}` not closed")))?;
            i += close + 2;
        } else {
            while i < chars.len() && !chars[i].is_whitespace() {
                i += 1;
            }
        }
        out.push((start + 1, chars[start..i].iter().collect()));
    }
    Ok(out)
}

/// One item; `leading`: first on its line, or after a line advance (a marker there is
/// primary).
fn item(token: &str, marker: char, leading: bool) -> Result<Item, String> {
    if let Some(text) = token
        .strip_prefix(marker)
        .and_then(|t| t.strip_suffix(marker))
    {
        if text.is_empty() {
            return Err("an empty marker".into());
        }
        return Ok(if leading {
            Item::Primary(text.to_string())
        } else {
            Item::Secondary(text.to_string())
        });
    }
    let lower = token.to_ascii_lowercase();
    if lower == "w" {
        return Ok(Item::Whitespace);
    }
    let count = |digits: &str, what: &str| -> Result<usize, String> {
        match digits.parse::<usize>() {
            Ok(n) if n >= 1 => Ok(n),
            _ => Err(format!("`{token}`: {what} takes a whole number from 1")),
        }
    };
    if let Some(n) = lower.strip_prefix('l') {
        return Ok(Item::Advance(count(n, "a line advance")?));
    }
    if let Some(n) = lower.strip_prefix('t') {
        return Ok(Item::Tab(count(n, "a tab")?));
    }
    let named = |close: char| -> Result<(Option<String>, String), String> {
        let end = token[1..].find(close).map(|i| i + 1).ok_or_else(|| {
            format!("`{token}`: the observation's name is not closed by `{close}`")
        })?;
        let name = &token[1..end];
        if name.is_empty() {
            return Err(format!("`{token}`: an observation without a name"));
        }
        let name = (!name.eq_ignore_ascii_case("dum")).then(|| name.to_string());
        Ok((name, token[end + 1..].to_string()))
    };
    let columns = |rest: &str| -> Result<(usize, usize), String> {
        let (a, b) = rest
            .split_once(':')
            .ok_or_else(|| format!("`{token}`: columns are written `c1:c2`"))?;
        let (a, b) = (count(a, "a column")?, count(b, "a column")?);
        if a > b {
            return Err(format!("`{token}`: the first column is after the last"));
        }
        Ok((a, b))
    };
    match token.chars().next() {
        Some('!') => {
            let (name, rest) = named('!')?;
            if !rest.is_empty() {
                return Err(format!("`{token}`: text after the observation's name"));
            }
            Ok(Item::Read(name, Reading::NonFixed))
        }
        Some('[') => {
            let (name, rest) = named(']')?;
            let (a, b) = columns(&rest)?;
            Ok(Item::Read(name, Reading::Fixed(a, b)))
        }
        Some('(') => {
            let (name, rest) = named(')')?;
            let (a, b) = columns(&rest)?;
            Ok(Item::Read(name, Reading::SemiFixed(a, b)))
        }
        _ => Err(format!("`{token}` is no instruction")),
    }
}

fn blank(c: u8) -> bool {
    c == b' ' || c == b'\t'
}

/// Where `needle` first starts in `row` at or after `from`.
fn find(row: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    if from > row.len() || needle.len() > row.len() - from {
        return None;
    }
    row[from..]
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|i| i + from)
}

/// The number `reading` takes on `row` with the cursor before `at`, and where the cursor
/// goes after it.
fn read_number(row: &[u8], at: usize, reading: Reading) -> Result<(f64, usize), String> {
    match reading {
        Reading::Fixed(a, b) => {
            if a > row.len() {
                return Err(format!("columns {a}:{b} are past the line's end"));
            }
            let field = &row[a - 1..b.min(row.len())];
            Ok((number(field)?, b))
        }
        Reading::SemiFixed(a, b) => {
            let start = (a - 1..b.min(row.len()))
                .find(|&i| !blank(row[i]))
                .ok_or_else(|| format!("nothing in columns {a}:{b}"))?;
            non_fixed(row, start)
        }
        Reading::NonFixed => {
            let start = (at..row.len())
                .find(|&i| !blank(row[i]))
                .ok_or_else(|| "no number after the cursor".to_string())?;
            non_fixed(row, start)
        }
    }
}

/// The number from `start` to the next blank, comma or the line's end.
fn non_fixed(row: &[u8], start: usize) -> Result<(f64, usize), String> {
    let end = (start..row.len())
        .find(|&i| blank(row[i]) || row[i] == b',')
        .unwrap_or(row.len());
    Ok((number(&row[start..end])?, end))
}

/// A number as Fortran reads one (`D` exponents too); anything else is refused.
fn number(field: &[u8]) -> Result<f64, String> {
    let text = String::from_utf8_lossy(field);
    let text = text.trim();
    let plain = text.replace(['d', 'D'], "e");
    let fortran = !plain.is_empty()
        && plain.chars().any(|c| c.is_ascii_digit())
        && plain
            .chars()
            .all(|c| c.is_ascii_digit() || "+-.eE".contains(c));
    match plain.parse::<f64>() {
        Ok(v) if fortran && v.is_finite() => Ok(v),
        _ => Err(format!("`{text}` is not a number")),
    }
}
