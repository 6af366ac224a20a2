//! Code that a reader can hold: no function of the workspace's non-test code is longer than
//! [`MOST_FUNCTION_LINES`] (but the tables named in [`TABLES`]), and no source file holds
//! more than [`MOST_FILE_CODE_LINES`] lines of code (blank and comment lines not counted).
//! A longer function is cut into named steps, a longer file into the concerns it holds.

use crate::common::*;
use std::path::{Path, PathBuf};

/// Lines of a function, from its `fn` line to its closing brace.
const MOST_FUNCTION_LINES: usize = 80;

/// Lines of code of a source file, without its inline `mod tests`.
const MOST_FILE_CODE_LINES: usize = 600;

/// Functions that are tables, read best whole: (file, function).
const TABLES: [(&str, &str); 1] = [
    // The Furuta pendulum's parameters: one entry per parameter with its unit and meaning.
    ("model/src/models/furuta.rs", "new"),
];

/// The folders of the workspace's non-test code.
const SOURCES: [&str; 9] = [
    "src",
    "proto/src",
    "security/src",
    "sandbox/src",
    "model/src",
    "worker/src",
    "coordinator/engine/src",
    "coordinator/analysis/src",
    "coordinator/service/src",
];

/// Every `.rs` file under `dir` that is not a test module of its own.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap();
        if path.is_dir() {
            if name != "tests" {
                sources(&path, out);
            }
        } else if name.ends_with(".rs") && name != "tests.rs" && !name.ends_with("_tests.rs") {
            out.push(path);
        }
    }
}

/// The lines of `text` with comments, string and character literals blanked out (their
/// braces and semicolons would mislead the count), and without an inline `mod tests`.
fn skeleton(text: &str) -> Vec<String> {
    let text = match text.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &text[..i],
        None => text,
    };
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if chars[i] == '\n' {
                        out.push('\n');
                    }
                    i += 1;
                }
            }
        } else if c == 'r'
            && (next == Some('"') || next == Some('#'))
            && (!word_before(&chars, i) || (chars[i - 1] == 'b' && !word_before(&chars, i - 1)))
        {
            // A raw string: r"…", r#"…"# or br"…", closed by a quote and as many hashes.
            let hashes = chars[i + 1..].iter().take_while(|&&h| h == '#').count();
            if chars.get(i + 1 + hashes) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            i += 2 + hashes;
            while i < chars.len() {
                if chars[i] == '"'
                    && chars[i + 1..].iter().take_while(|&&h| h == '#').count() >= hashes
                {
                    i += 1 + hashes;
                    break;
                }
                if chars[i] == '\n' {
                    out.push('\n');
                }
                i += 1;
            }
            out.push_str("\"\"");
        } else if c == '"' {
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                if chars[i] == '\\' {
                    i += 1;
                }
                if chars.get(i) == Some(&'\n') {
                    out.push('\n');
                }
                i += 1;
            }
            i += 1;
            out.push_str("\"\"");
        } else if c == '\'' {
            // A character literal ('x', '\n', '\u{7f}'), not a lifetime ('a).
            let end = if next == Some('\\') {
                // The escaped character may itself be a quote: '\''.
                chars
                    .get(i + 3..)
                    .and_then(|rest| rest.iter().position(|&q| q == '\''))
                    .map(|p| i + 3 + p)
            } else if chars.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(end) => {
                    out.push_str("' '");
                    i = end + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out.lines().map(str::to_string).collect()
}

/// Whether the character before `i` continues an identifier (the `r` of `for"` is no raw
/// string's).
fn word_before(chars: &[char], i: usize) -> bool {
    i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_')
}

/// The name of the function a skeleton line declares, if it declares one.
fn declared_fn(line: &str) -> Option<String> {
    let mut words = line.split_whitespace().peekable();
    while let Some(word) = words.next() {
        let qualifier = word.starts_with("pub")
            || matches!(
                word,
                "async" | "const" | "unsafe" | "extern" | "default" | "\"\""
            );
        if word == "fn" {
            let name = words.next()?;
            let name: String = name
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            return (!name.is_empty()).then_some(name);
        }
        if !qualifier {
            return None;
        }
    }
    None
}

/// Every function with a body in `lines` (a skeleton): its name, first line (from 1) and
/// length in lines.
fn functions(lines: &[String]) -> Vec<(String, usize, usize)> {
    let mut found = Vec::new();
    for (start, line) in lines.iter().enumerate() {
        let Some(name) = declared_fn(line) else {
            continue;
        };
        let mut depth = 0i64;
        // Parentheses and brackets of the signature: `[u8; 32]` holds a `;`.
        let mut nested = 0i64;
        let mut opened = false;
        'lines: for (end, line) in lines.iter().enumerate().skip(start) {
            for c in line.chars() {
                match c {
                    '(' | '[' if !opened => nested += 1,
                    ')' | ']' if !opened => nested -= 1,
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    // A declaration without a body (a trait's method, an extern function).
                    ';' if !opened && nested == 0 => break 'lines,
                    _ => {}
                }
                if opened && depth == 0 {
                    found.push((name.clone(), start + 1, end - start + 1));
                    break 'lines;
                }
            }
        }
    }
    found
}

/// Lines of code in a skeleton: neither blank nor only a comment (already blanked).
fn code_lines(lines: &[String]) -> usize {
    lines.iter().filter(|l| !l.trim().is_empty()).count()
}

#[test]
fn the_reading_finds_functions_and_skips_what_is_not_code() {
    let body = "    x += 1;\n".repeat(85);
    let text = format!(
        "/// Doc with a brace {{\nfn long<'a>(s: &'a str) -> char {{\n    let q = '{{';\n    \
         let t = \"}} ; {{\";\n    let r = r#\"}}\"#;\n    // }}\n{body}    '}}'\n}}\n\
         trait T {{\n    fn declared(&self);\n}}\npub(crate) async fn short() {{}}\n\
         fn keyed(k: [u8; 32]) -> char {{\n    let _ = br\"}}\";\n    '\\''\n}}\n\
         #[cfg(test)]\nmod tests {{\n    fn ignored() {{}}\n}}\n"
    );
    let lines = skeleton(&text);
    let found = functions(&lines);
    assert_eq!(
        found,
        vec![
            ("long".to_string(), 2, 92),
            ("short".to_string(), 97, 1),
            ("keyed".to_string(), 98, 4)
        ],
        "{lines:#?}"
    );
}

#[test]
fn functions_and_files_fit_on_a_readers_screen() {
    let repo = repo();
    let mut files = Vec::new();
    for folder in SOURCES {
        sources(&repo.join(folder), &mut files);
    }
    assert!(files.len() > 100, "only {} source files found", files.len());
    let mut too_long = Vec::new();
    let mut longest = (0, String::new());
    for file in &files {
        let relative = file
            .strip_prefix(&repo)
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        let lines = skeleton(&std::fs::read_to_string(file).unwrap());
        let code = code_lines(&lines);
        if code > MOST_FILE_CODE_LINES {
            too_long.push(format!("{relative}: {code} lines of code"));
        }
        for (name, line, length) in functions(&lines) {
            if length > longest.0 {
                longest = (length, format!("{relative}:{line} {name}"));
            }
            if length > MOST_FUNCTION_LINES && !TABLES.contains(&(relative.as_str(), name.as_str()))
            {
                too_long.push(format!("{relative}:{line} fn {name}: {length} lines"));
            }
        }
    }
    println!("longest function: {} ({} lines)", longest.1, longest.0);
    assert!(
        too_long.is_empty(),
        "longer than a reader can hold (functions over {MOST_FUNCTION_LINES} lines, files over \
         {MOST_FILE_CODE_LINES} lines of code):\n{}",
        too_long.join("\n")
    );
}
