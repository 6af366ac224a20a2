//! The coordinator's top-level modules form layers: no module reaches, through `crate::`
//! paths in its non-test code, a module that reaches back to it (docs/architecture.md draws
//! the graph this test reads).

use crate::common::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The files of modules declared `#[cfg(test)] mod name;` (tests and test helpers).
fn test_modules(files: &[PathBuf]) -> BTreeSet<PathBuf> {
    let mut tests = BTreeSet::new();
    for file in files {
        let text = std::fs::read_to_string(file).unwrap();
        let stem = file.file_stem().unwrap().to_str().unwrap();
        let dir = file.parent().unwrap();
        let base = if stem == "mod" || stem == "lib" {
            dir.to_path_buf()
        } else {
            dir.join(stem)
        };
        let lines: Vec<&str> = text.lines().map(str::trim).collect();
        for pair in lines.windows(2) {
            if pair[0] != "#[cfg(test)]" {
                continue;
            }
            let declared = pair[1]
                .trim_start_matches("pub(crate) ")
                .trim_start_matches("pub ");
            if let Some(name) = declared
                .strip_prefix("mod ")
                .and_then(|m| m.strip_suffix(';'))
            {
                tests.insert(base.join(format!("{name}.rs")));
                tests.insert(base.join(name).join("mod.rs"));
            }
        }
    }
    tests
}

/// The code of `file` without comments and without its inline `#[cfg(test)] mod tests`.
fn code(file: &Path) -> String {
    let text = std::fs::read_to_string(file).unwrap();
    let text = match text.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    text.lines()
        .map(|l| l.split("//").next().unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Which top-level modules each top-level module of the coordinator names.
fn module_graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = repo().join("coordinator/src");
    let mut modules = BTreeSet::new();
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        if name != "lib" {
            modules.insert(name);
        }
    }
    let mut files = Vec::new();
    sources(&src, &mut files);
    let tests = test_modules(&files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        let relative = file.strip_prefix(&src).unwrap();
        let first = relative.components().next().unwrap().as_os_str();
        let module = Path::new(first).file_stem().unwrap().to_str().unwrap();
        if module == "lib" || tests.contains(file) || file.ends_with("tests.rs") {
            continue;
        }
        let code = code(file);
        let named = graph.entry(module.to_string()).or_default();
        // `crate::name` anywhere, and the names inside `use crate::{a, b::c}`.
        for part in code.split("crate::").skip(1) {
            let braced = part.strip_prefix('{').map(|b| b.split('}').next().unwrap());
            let names: Vec<&str> = match braced {
                Some(list) => list
                    .split(',')
                    .map(|n| n.trim().split("::").next().unwrap().trim())
                    .collect(),
                None => vec![part
                    .split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .next()
                    .unwrap()],
            };
            for n in names {
                if n != module && modules.contains(n) {
                    named.insert(n.to_string());
                }
            }
        }
    }
    graph
}

/// A cycle of the graph, if it has one (depth-first search).
fn cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == node) {
            let mut found = path[i..].to_vec();
            found.push(node.to_string());
            return Some(found);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(found) = visit(next, graph, path, done) {
                return Some(found);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

#[test]
fn the_coordinators_modules_import_no_circle() {
    let graph = module_graph();
    for (module, named) in &graph {
        println!(
            "{module} -> {}",
            Vec::from_iter(named.iter().cloned()).join(", ")
        );
    }
    // The reading finds the edges it should: a test that cannot see edges proves nothing.
    assert!(graph["diagnosis"].contains("residuals"), "{graph:?}");
    assert!(graph["profile"].contains("residuals"), "{graph:?}");
    assert!(graph["server"].contains("web"), "{graph:?}");
    assert!(graph["calibration"].contains("outcome"), "{graph:?}");
    assert_eq!(cycle(&graph), None);
}

#[test]
fn the_cycle_finder_finds_a_circle() {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    graph.entry("a".into()).or_default().insert("b".into());
    graph.entry("b".into()).or_default().insert("c".into());
    assert_eq!(cycle(&graph), None);
    graph.entry("c".into()).or_default().insert("a".into());
    assert_eq!(
        cycle(&graph),
        Some(vec!["a".into(), "b".into(), "c".into(), "a".into()])
    );
}
