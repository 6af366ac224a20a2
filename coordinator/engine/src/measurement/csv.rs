//! CSV measurements.
//!
//! The format accepted:
//!
//! * a header row naming the columns is required; columns may come in any order;
//! * lines before the header that are blank or start with `#` are comments;
//! * cells are separated by commas, or by `;` or tabs when the header uses those more
//!   than commas; cells may be quoted (`"time"`), surrounding whitespace is trimmed;
//! * numbers use a decimal point (`1.5`, `-2e-3`); `NaN`, `inf` and the like parse but
//!   are rejected as non-finite, as are numbers too large for an `f64`;
//! * blank lines (including whitespace-only ones) are ignored wherever they are, so
//!   trailing newlines do no harm;
//! * every row must have as many cells as the header; a UTF-8 byte order mark is
//!   skipped.
//!
//! Line numbers in errors are 1-based and count every line of the file, comments
//! included.

use std::path::Path;

use super::{check_finite, check_time_step, Location, Measurement, MeasurementError, TimeOrder};

/// Reads a CSV measurement from the bytes of `path`.
pub(super) fn read(
    path: &Path,
    bytes: &[u8],
    time_column: &str,
    columns: &[&str],
) -> Result<Measurement, MeasurementError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let header = find_header(bytes).ok_or_else(|| MeasurementError::MissingHeader {
        path: path.to_owned(),
    })?;
    let data = &bytes[header.offset..];
    let mut records = Records {
        path,
        reader: reader_of(data, header.delimiter),
        lines: LineIndex::new(data, header.line),
        header_line: header.line,
    };

    let mut record = ::csv::ByteRecord::new();
    // find_header saw a non-blank line here, so the reader yields a record.
    records.read(&mut record)?;
    let names: Vec<String> = record.iter().map(cell_text).collect();

    let find_column = |name: &str| column_index(path, header.line, &names, name);
    let time_index = find_column(time_column)?;
    let column_indices = columns
        .iter()
        .map(|name| find_column(name))
        .collect::<Result<Vec<usize>, _>>()?;
    let wanted = Wanted {
        header_len: names.len(),
        time: (time_index, time_column),
        indices: &column_indices,
        columns,
    };
    let (time, values) = records.rows(&mut record, &wanted)?;

    if time.is_empty() {
        return Err(MeasurementError::NoRows {
            path: path.to_owned(),
            header_line: header.line,
        });
    }
    Ok(Measurement {
        source: path.to_owned(),
        time,
        columns: columns
            .iter()
            .map(|name| name.to_string())
            .zip(values)
            .collect(),
    })
}

/// The records of a CSV file from its header on, with what is needed to place them in
/// the file for error messages.
struct Records<'p, 'a> {
    path: &'p Path,
    reader: ::csv::Reader<&'a [u8]>,
    lines: LineIndex<'a>,
    /// 1-based line number of the header.
    header_line: usize,
}

/// The cells a row is read for, and how many cells each row must have.
struct Wanted<'w> {
    /// Cells of the header row.
    header_len: usize,
    /// Index and name of the time column.
    time: (usize, &'w str),
    /// Indices of the requested columns, in the order of `columns`.
    indices: &'w [usize],
    columns: &'w [&'w str],
}

impl Records<'_, '_> {
    /// The file line of a record at reader position `position` (the header's when the
    /// reader reports none), for error messages.
    fn line_of(&self, position: Option<&::csv::Position>) -> usize {
        position.map_or(self.header_line, |position| {
            self.lines
                .line_at(usize::try_from(position.byte()).unwrap_or(usize::MAX))
        })
    }

    /// Reads the next record into `record` (`false` at the end), a reader error becoming
    /// a malformed-CSV error at its line.
    fn read(&mut self, record: &mut ::csv::ByteRecord) -> Result<bool, MeasurementError> {
        self.reader
            .read_byte_record(record)
            .map_err(|error| MeasurementError::MalformedCsv {
                path: self.path.to_owned(),
                line: self.line_of(error.position()),
                detail: error.to_string(),
            })
    }

    /// Reads every data row after the header: the times, checked to increase strictly,
    /// and the values of each wanted column. Blank rows are skipped.
    fn rows(
        &mut self,
        record: &mut ::csv::ByteRecord,
        wanted: &Wanted<'_>,
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>), MeasurementError> {
        let path = self.path;
        let (time_index, time_column) = wanted.time;
        let mut time = Vec::new();
        let mut values: Vec<Vec<f64>> = vec![Vec::new(); wanted.columns.len()];
        let mut previous_time: Option<(Location, f64)> = None;
        while self.read(record)? {
            if record.iter().all(<[u8]>::is_empty) {
                continue;
            }
            let line = self.line_of(record.position());
            if record.len() != wanted.header_len {
                return Err(MeasurementError::RaggedRow {
                    path: path.to_owned(),
                    line,
                    expected: wanted.header_len,
                    found: record.len(),
                });
            }
            let location = Location::Line(line);
            let cell_value =
                |index: usize, column: &str| cell_number(path, line, record, index, column);

            let sample_time = cell_value(time_index, time_column)?;
            check_time_step(
                path,
                time_column,
                previous_time,
                location,
                sample_time,
                TimeOrder::Strict,
            )?;
            previous_time = Some((location, sample_time));
            time.push(sample_time);
            for ((&index, name), column_values) in
                wanted.indices.iter().zip(wanted.columns).zip(&mut values)
            {
                column_values.push(cell_value(index, name)?);
            }
        }
        Ok((time, values))
    }
}

/// A reader of the records from the header on: no header row of its own (the header is read
/// as the first record), rows of any length (checked against the header's), cells trimmed.
fn reader_of(data: &[u8], delimiter: u8) -> ::csv::Reader<&[u8]> {
    ::csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(::csv::Trim::All)
        .delimiter(delimiter)
        .from_reader(data)
}

/// The index of the header's one column called `name` (missing or named twice: an error at
/// the header's line).
fn column_index(
    path: &Path,
    header_line: usize,
    names: &[String],
    name: &str,
) -> Result<usize, MeasurementError> {
    let matches: Vec<usize> = names
        .iter()
        .enumerate()
        .filter(|(_, candidate)| candidate.as_str() == name)
        .map(|(index, _)| index)
        .collect();
    match matches.as_slice() {
        [index] => Ok(*index),
        [] => Err(MeasurementError::MissingColumn {
            path: path.to_owned(),
            line: header_line,
            column: name.to_owned(),
            available: names.to_vec(),
        }),
        _ => Err(MeasurementError::DuplicateColumn {
            path: path.to_owned(),
            line: header_line,
            column: name.to_owned(),
            count: matches.len(),
        }),
    }
}

/// The finite number in cell `index` of `record` (of the file's line `line`), in `column`.
fn cell_number(
    path: &Path,
    line: usize,
    record: &::csv::ByteRecord,
    index: usize,
    column: &str,
) -> Result<f64, MeasurementError> {
    let text = cell_text(record.get(index).unwrap_or_default());
    // `NaN` and `inf` parse, and are rejected below with a message that says why.
    let value = text
        .parse::<f64>()
        .map_err(|_| MeasurementError::NonNumeric {
            path: path.to_owned(),
            line,
            column: column.to_owned(),
            text,
        })?;
    check_finite(path, Location::Line(line), column, value)?;
    Ok(value)
}

/// The header row: where it starts and how its cells are separated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Header {
    /// Byte offset of the header's first byte.
    offset: usize,
    /// 1-based line number of the header.
    line: usize,
    delimiter: u8,
}

/// Finds the first line that is neither blank nor a `#` comment.
fn find_header(bytes: &[u8]) -> Option<Header> {
    let mut offset = 0;
    for (index, line) in bytes.split_inclusive(|&byte| byte == b'\n').enumerate() {
        let content = line.trim_ascii();
        if !content.is_empty() && !content.starts_with(b"#") {
            return Some(Header {
                offset,
                line: index + 1,
                delimiter: delimiter_of(content),
            });
        }
        offset += line.len();
    }
    None
}

/// The separator the header uses most among comma, semicolon and tab; comma on a tie
/// (a single-column header has none of them).
fn delimiter_of(header: &[u8]) -> u8 {
    let count = |delimiter: u8| header.iter().filter(|&&byte| byte == delimiter).count();
    let commas = count(b',');
    let semicolons = count(b';');
    let tabs = count(b'\t');
    if semicolons > commas && semicolons >= tabs {
        b';'
    } else if tabs > commas && tabs > semicolons {
        b'\t'
    } else {
        b','
    }
}

/// A trimmed cell as text. Quotes that whitespace kept the reader from recognising
/// (` "time" `) are removed, with `""` standing for one `"` inside them.
fn cell_text(cell: &[u8]) -> String {
    let text = String::from_utf8_lossy(cell);
    match text
        .strip_prefix('"')
        .and_then(|inner| inner.strip_suffix('"'))
    {
        Some(inner) => inner.trim().replace("\"\"", "\""),
        None => text.into_owned(),
    }
}

/// Turns byte offsets into 1-based file lines.
struct LineIndex<'a> {
    text: &'a [u8],
    /// Offsets in `text` at which lines start.
    starts: Vec<usize>,
    /// Line number of the first line of `text`.
    first_line: usize,
}

impl<'a> LineIndex<'a> {
    fn new(text: &'a [u8], first_line: usize) -> Self {
        let starts = std::iter::once(0)
            .chain(
                text.iter()
                    .enumerate()
                    .filter(|(_, &byte)| byte == b'\n')
                    .map(|(index, _)| index + 1),
            )
            .collect();
        LineIndex {
            text,
            starts,
            first_line,
        }
    }

    /// The line of the record the reader reports at `offset`. The reader's offset
    /// precedes the empty lines it skipped on the way, so those are stepped over.
    fn line_at(&self, offset: usize) -> usize {
        let mut offset = offset.min(self.text.len());
        while matches!(self.text.get(offset), Some(b'\r' | b'\n')) {
            offset += 1;
        }
        let lines_started = self.starts.partition_point(|&start| start <= offset);
        self.first_line + lines_started.saturating_sub(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("data/run1.csv")
    }

    fn load(
        text: &str,
        time_column: &str,
        columns: &[&str],
    ) -> Result<Measurement, MeasurementError> {
        read(&path(), text.as_bytes(), time_column, columns)
    }

    fn load_err(text: &str, columns: &[&str]) -> MeasurementError {
        match load(text, "t", columns) {
            Ok(measurement) => panic!("expected an error, got {measurement:?}"),
            Err(error) => error,
        }
    }

    #[test]
    fn reads_requested_columns_in_requested_order() {
        let loaded = load("t,a,b,c\n0,1,2,3\n0.5,4,5,6\n", "t", &["c", "a"]).expect("valid");
        assert_eq!(loaded.source, path());
        assert_eq!(loaded.time, vec![0.0, 0.5]);
        assert_eq!(
            loaded.columns,
            vec![
                ("c".to_owned(), vec![3.0, 6.0]),
                ("a".to_owned(), vec![1.0, 4.0])
            ]
        );
    }

    #[test]
    fn time_column_may_sit_anywhere() {
        let loaded = load("a,t\n1,0\n2,1\n", "t", &["a"]).expect("valid");
        assert_eq!(loaded.time, vec![0.0, 1.0]);
        assert_eq!(loaded.column("a"), Some(&[1.0, 2.0][..]));
    }

    #[test]
    fn unrequested_columns_are_not_validated() {
        let loaded = load("t,x,notes\n0,1,fine\n1,2,NaN\n2,3,\n", "t", &["x"]).expect("valid");
        assert_eq!(loaded.column("x"), Some(&[1.0, 2.0, 3.0][..]));
    }

    #[test]
    fn whitespace_quotes_comments_and_blank_lines_are_tolerated() {
        let text = "\u{feff}# recorded 2024-05-01\n\n  # rig 2\n \"t\" , \"x\" \r\n 0 , 1.5 \r\n\r\n1,-2e-1\r\n  \n\n";
        let loaded = load(text, "t", &["x"]).expect("valid");
        assert_eq!(loaded.time, vec![0.0, 1.0]);
        assert_eq!(loaded.column("x"), Some(&[1.5, -0.2][..]));
    }

    #[test]
    fn semicolons_and_tabs_are_recognised_from_the_header() {
        let semicolons = load("t;x;y\n0;1;2\n1;3;4\n", "t", &["y"]).expect("semicolons");
        assert_eq!(semicolons.column("y"), Some(&[2.0, 4.0][..]));
        let tabs = load("t\tx\n0\t1\n1\t3\n", "t", &["x"]).expect("tabs");
        assert_eq!(tabs.column("x"), Some(&[1.0, 3.0][..]));
        let single_column = load("t\n0\n1\n", "t", &[]).expect("single column");
        assert_eq!(single_column.time, vec![0.0, 1.0]);
        assert!(single_column.columns.is_empty());
    }

    #[test]
    fn delimiter_choice() {
        assert_eq!(delimiter_of(b"a,b,c"), b',');
        assert_eq!(delimiter_of(b"a;b;c"), b';');
        assert_eq!(delimiter_of(b"a\tb\tc"), b'\t');
        assert_eq!(delimiter_of(b"a;b,c"), b',');
        assert_eq!(
            delimiter_of(b"time (s);angle, arm;angle, pendulum;t2"),
            b';'
        );
        assert_eq!(delimiter_of(b"a"), b',');
    }

    #[test]
    fn missing_column_lists_the_header() {
        let error = load_err("# comment\nt,x,y\n0,1,2\n", &["x", "z"]);
        assert!(
            matches!(&error, MeasurementError::MissingColumn { line: 2, column, .. } if column == "z")
        );
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 2: the header has no column \"z\"; its columns are: \"t\", \"x\", \"y\""
        );
    }

    #[test]
    fn missing_time_column_is_reported_too() {
        let error = match load("time,x\n0,1\n", "t", &["x"]) {
            Err(error) => error,
            Ok(_) => panic!("no column t"),
        };
        assert!(error.to_string().contains("no column \"t\""), "{error}");
    }

    #[test]
    fn ambiguous_column_is_an_error() {
        let error = load_err("t,x,x\n0,1,2\n", &["x"]);
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 1: the header names column \"x\" 2 times; rename the duplicates"
        );
        // Duplicates among columns nobody asked for do not matter.
        assert!(load("t,x,y,y\n0,1,2,3\n", "t", &["x"]).is_ok());
    }

    #[test]
    fn non_numeric_cell_names_line_column_and_text() {
        let error = load_err("t,x\n0,1\n1,abc\n", &["x"]);
        assert!(
            matches!(&error, MeasurementError::NonNumeric { line: 3, text, .. } if text == "abc")
        );
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 3, column \"x\": \"abc\" is not a number"
        );
        let error = load_err("t,x\n0,1\n1, \n", &["x"]);
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 3, column \"x\": the cell is empty; expected a number"
        );
        let error = load_err("t;x\n0;1,5\n", &["x"]);
        assert!(error.to_string().contains("write \"1.5\""), "{error}");
    }

    #[test]
    fn invalid_utf8_cell_is_non_numeric() {
        let error = read(&path(), b"t,x\n0,\xff\xfe\n", "t", &["x"]).expect_err("bad bytes");
        assert!(
            matches!(error, MeasurementError::NonNumeric { line: 2, .. }),
            "{error}"
        );
    }

    #[test]
    fn nan_and_infinities_are_rejected() {
        for text in ["NaN", "nan", "inf", "-inf", "+Infinity", "1e400"] {
            let error = load_err(&format!("t,x\n0,1\n1,{text}\n"), &["x"]);
            assert!(
                matches!(&error, MeasurementError::NonFinite { location: Location::Line(3), column, .. } if column == "x"),
                "{text}: {error}"
            );
            let message = error.to_string();
            assert!(
                message.starts_with("data/run1.csv line 3, column \"x\": value "),
                "{message}"
            );
            assert!(message.contains("is not finite"), "{message}");
        }
        let error = load_err("t,x\n0,1\nnan,2\n", &["x"]);
        assert!(
            matches!(&error, MeasurementError::NonFinite { column, .. } if column == "t"),
            "{error}"
        );
    }

    #[test]
    fn time_must_strictly_increase() {
        let error = load_err("t,x\n0,1\n0.5,1\n0.5,2\n", &["x"]);
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 4: time (\"t\") must strictly increase, but 0.5 follows 0.5 at line 3"
        );
        let error = load_err("t,x\n0,1\n0.5,1\n\n# note\n0.25,2\n", &["x"]);
        let message = error.to_string();
        // `#` lines inside the data are rows like any other, not comments.
        assert!(message.contains("line 5"), "{message}");
        let error = load_err("t,x\n0,1\n0.5,1\n\n0.25,2\n", &["x"]);
        assert!(
            matches!(
                error,
                MeasurementError::TimeNotIncreasing {
                    previous_location: Location::Line(3),
                    location: Location::Line(5),
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn ragged_rows_are_rejected() {
        let error = load_err("t,x,y\n0,1,2\n1,2\n", &["x"]);
        assert_eq!(
            error.to_string(),
            "data/run1.csv line 3: the row has 2 cells but the header has 3 columns"
        );
        let error = load_err("t,x\n0,1,2\n", &["x"]);
        assert!(matches!(
            error,
            MeasurementError::RaggedRow {
                line: 2,
                expected: 2,
                found: 3,
                ..
            }
        ));
    }

    #[test]
    fn header_without_rows_is_empty_data() {
        for text in ["t,x\n", "t,x", "# c\nt,x\n\n   \n"] {
            let error = load_err(text, &["x"]);
            assert!(
                matches!(error, MeasurementError::NoRows { .. }),
                "{text:?}: {error}"
            );
        }
        assert_eq!(
            load_err("#c\nt,x\n", &["x"]).to_string(),
            "data/run1.csv: no data rows after the header on line 2"
        );
    }

    #[test]
    fn file_without_header_is_reported() {
        for text in ["", "\n\n", "# only a comment\n", "\u{feff}"] {
            let error = load_err(text, &["x"]);
            assert!(
                matches!(error, MeasurementError::MissingHeader { .. }),
                "{text:?}: {error}"
            );
        }
    }

    #[test]
    fn line_index_counts_every_line() {
        let text = b"a\n\n\r\nb\nc";
        let lines = LineIndex::new(text, 3);
        assert_eq!(lines.line_at(0), 3);
        // A reader that skipped the blank lines reports the offset of the first one.
        assert_eq!(lines.line_at(2), 6);
        assert_eq!(lines.line_at(5), 6);
        assert_eq!(lines.line_at(7), 7);
        assert_eq!(lines.line_at(1000), 7);
    }

    #[test]
    fn quoted_cells_lose_their_quotes() {
        assert_eq!(cell_text(b"\"a \"\"b\"\" \""), "a \"b\"");
        assert_eq!(cell_text(b"\""), "\"");
        let loaded = load(" \"t\" , \"x\" \n \"0\" , \" 1.5\" \n", "t", &["x"]).expect("valid");
        assert_eq!(loaded.column("x"), Some(&[1.5][..]));
    }

    #[test]
    fn multi_line_quoted_cells_keep_line_numbers_right() {
        let error = load_err("t,x,note\n0,1,\"two\nlines\"\n1,oops,n\n", &["x"]);
        assert!(
            matches!(error, MeasurementError::NonNumeric { line: 4, .. }),
            "{error}"
        );
    }

    #[test]
    fn never_panics_on_mangled_input() {
        let valid = "# c\nt;x;y\n0;1;2\n0.5;\"3\";4\n1;5;6\n".as_bytes();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for cut in 0..=valid.len() {
            let _ = read(&path(), &valid[..cut], "t", &["x", "y"]);
        }
        for _ in 0..2000 {
            let mut mangled = valid.to_vec();
            for _ in 0..(next() % 4 + 1) {
                let index = (next() as usize) % mangled.len();
                mangled[index] = (next() & 0xff) as u8;
            }
            let _ = read(&path(), &mangled, "t", &["x", "y"]);
        }
    }
}
