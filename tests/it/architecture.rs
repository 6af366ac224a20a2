//! The coordinator's crates and their top-level modules form layers: no module reaches,
//! through the paths in its non-test code, a module that reaches back to it; no module names
//! one of a crate above its own; only the service crate depends on an async runtime or a
//! network stack (docs/architecture.md draws the graph this test reads).

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

/// The coordinator's crates, bottom up: each may name only those before it.
const CRATES: [(&str, &str); 3] = [
    ("calib_engine", "coordinator/engine"),
    ("calib_analysis", "coordinator/analysis"),
    ("calib_service", "coordinator/service"),
];

/// The top-level modules of a crate's `src/`.
fn modules_of(src: &Path) -> BTreeSet<String> {
    let mut modules = BTreeSet::new();
    for entry in std::fs::read_dir(src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        if name != "lib" {
            modules.insert(name);
        }
    }
    modules
}

/// The modules `code` names through `prefix::name` anywhere, and the names inside
/// `use prefix::{a, b::c}`.
fn named_after(code: &str, prefix: &str) -> Vec<String> {
    let mut names = Vec::new();
    for part in code.split(prefix).skip(1) {
        match part.strip_prefix('{').map(|b| b.split('}').next().unwrap()) {
            Some(list) => names.extend(
                list.split(',')
                    .map(|n| n.trim().split("::").next().unwrap().trim().to_string()),
            ),
            None => names.push(
                part.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .next()
                    .unwrap()
                    .to_string(),
            ),
        }
    }
    names
}

/// Which top-level modules each top-level module of the coordinator's crates names, and the
/// crate of each module.
fn module_graph() -> (
    BTreeMap<String, BTreeSet<String>>,
    BTreeMap<String, &'static str>,
) {
    let mut crate_of: BTreeMap<String, &'static str> = BTreeMap::new();
    for (name, folder) in CRATES {
        for module in modules_of(&repo().join(folder).join("src")) {
            assert!(
                crate_of.insert(module.clone(), name).is_none(),
                "module {module} in two crates"
            );
        }
    }
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (name, folder) in CRATES {
        let src = repo().join(folder).join("src");
        let mut files = Vec::new();
        sources(&src, &mut files);
        let tests = test_modules(&files);
        for file in &files {
            let relative = file.strip_prefix(&src).unwrap();
            let first = relative.components().next().unwrap().as_os_str();
            let module = Path::new(first).file_stem().unwrap().to_str().unwrap();
            if module == "lib" || tests.contains(file) || file.ends_with("tests.rs") {
                continue;
            }
            let code = code(file);
            let named = graph.entry(module.to_string()).or_default();
            let prefixes = ["crate::".to_string()]
                .into_iter()
                .chain(CRATES.iter().map(|(c, _)| format!("{c}::")));
            for prefix in prefixes {
                for n in named_after(&code, &prefix) {
                    let known = match prefix.as_str() {
                        "crate::" => crate_of.get(&n) == Some(&name),
                        other => crate_of.get(&n).is_some_and(|c| format!("{c}::") == other),
                    };
                    if n != module && known {
                        named.insert(n);
                    }
                }
            }
        }
    }
    (graph, crate_of)
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
    let (graph, crate_of) = module_graph();
    for (module, named) in &graph {
        println!(
            "{} {module} -> {}",
            crate_of[module],
            Vec::from_iter(named.iter().cloned()).join(", ")
        );
    }
    // The reading finds the edges it should, within a crate and across crates: a test that
    // cannot see edges proves nothing.
    assert!(graph["diagnosis"].contains("residuals"), "{graph:?}");
    assert!(graph["profile"].contains("residuals"), "{graph:?}");
    assert!(graph["server"].contains("web"), "{graph:?}");
    assert!(graph["calibration"].contains("outcome"), "{graph:?}");
    assert!(graph["diagnosis"].contains("calibration"), "{graph:?}");
    assert!(graph["api"].contains("report"), "{graph:?}");
    assert_eq!(cycle(&graph), None);
    // No module names one of a crate above its own.
    let rank = |c: &str| CRATES.iter().position(|(name, _)| *name == c).unwrap();
    for (module, named) in &graph {
        for n in named {
            assert!(
                rank(crate_of[n]) <= rank(crate_of[module]),
                "{module} ({}) names {n} ({}), a crate above it",
                crate_of[module],
                crate_of[n]
            );
        }
    }
}

/// The names of a crate's `[dependencies]` (not its dev-dependencies).
fn dependencies(folder: &str) -> BTreeSet<String> {
    let text = std::fs::read_to_string(repo().join(folder).join("Cargo.toml")).unwrap();
    let manifest: toml::Value = toml::from_str(&text).unwrap();
    manifest
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|d| d.keys().cloned().collect())
        .unwrap_or_default()
}

#[test]
fn only_the_service_crate_runs_async_code_or_serves() {
    let engine = dependencies("coordinator/engine");
    let analysis = dependencies("coordinator/analysis");
    let service = dependencies("coordinator/service");
    for (crate_, deps) in [("engine", &engine), ("analysis", &analysis)] {
        for async_or_network in ["tokio", "tonic", "axum", "calib-proto", "calib-service"] {
            assert!(
                !deps.contains(async_or_network),
                "the {crate_} crate depends on {async_or_network}"
            );
        }
    }
    assert!(!engine.contains("calib-analysis"));
    assert!(analysis.contains("calib-engine"));
    assert!(service.contains("tokio") && service.contains("calib-analysis"));
}

/// The packages `package` builds on, directly or through others, with the features the
/// workspace gives them (`cargo tree`, normal dependencies only), one name per entry.
fn dependency_tree(package: &str) -> BTreeSet<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = std::process::Command::new(cargo)
        .current_dir(repo())
        .args([
            "tree",
            "--offline",
            "--locked",
            "-e",
            "normal",
            "--prefix",
            "none",
        ])
        .args(["--format", "{p}", "-p", package])
        .output()
        .expect("cargo tree runs");
    assert!(
        output.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

#[test]
fn the_engine_the_analyses_and_the_models_build_on_no_runtime_network_or_protocol() {
    for package in ["calib-model", "calib-engine", "calib-analysis"] {
        let tree = dependency_tree(package);
        // The tree is read: the package itself and its own dependencies are in it.
        assert!(tree.contains(package), "{package}: {tree:?}");
        assert!(tree.contains("serde"), "{package}: {tree:?}");
        for banned in [
            "tokio",
            "tonic",
            "prost",
            "hyper",
            "h2",
            "axum",
            "calib-proto",
        ] {
            assert!(
                !tree.contains(banned),
                "{package} builds on {banned}, through: {:?}",
                path_to(package, banned)
            );
        }
        assert!(!tree.contains("calib-worker") && !tree.contains("calib-service"));
    }
    // The check can fail: the worker serves over gRPC.
    assert!(dependency_tree("calib-worker").contains("tonic"));
}

/// How `package` comes to build on `banned` (`cargo tree --invert`), for the message.
fn path_to(package: &str, banned: &str) -> String {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = std::process::Command::new(cargo)
        .current_dir(repo())
        .args([
            "tree",
            "--offline",
            "--locked",
            "-e",
            "normal",
            "-p",
            package,
        ])
        .args(["--invert", banned])
        .output()
        .expect("cargo tree runs");
    String::from_utf8_lossy(&output.stdout).into_owned()
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

/// The web app's modules (`coordinator/service/src/web/assets/js/`), by file name: each
/// one's text, and the names it imports by the module they come from.
type WebModules = BTreeMap<String, (String, Vec<(String, Vec<String>)>)>;

fn web_modules() -> WebModules {
    let dir = repo().join("coordinator/service/src/web/assets/js");
    let mut modules = BTreeMap::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "js") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let mut imports = Vec::new();
        let mut rest = text.as_str();
        while let Some(at) = rest.find("import {") {
            let statement = &rest[at..];
            let close = statement.find('}').expect("an import's closing brace");
            let names = statement["import {".len()..close]
                .split(',')
                .map(|n| n.trim().to_string())
                .filter(|n| !n.is_empty())
                .collect();
            let from = &statement[close..];
            let quote = from.find("from \"./").expect("a relative import") + "from \"./".len();
            let end = from[quote..].find('"').unwrap();
            imports.push((from[quote..quote + end].to_string(), names));
            rest = &from[quote + end..];
        }
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        modules.insert(name, (text, imports));
    }
    assert!(
        modules.len() >= 10,
        "the web app's modules: {:?}",
        modules.keys()
    );
    modules
}

/// Whether `text` holds `name` as a whole identifier.
fn holds_identifier(text: &str, name: &str) -> bool {
    let part = |c: char| c.is_alphanumeric() || c == '_' || c == '$';
    text.match_indices(name).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + name.len()..].chars().next();
        !before.is_some_and(part) && !after.is_some_and(part)
    })
}

/// The names a module of the web app exports (`export function f`, `export const x`, …).
fn exports(text: &str) -> BTreeSet<String> {
    let part = |c: char| c.is_alphanumeric() || c == '_' || c == '$';
    let mut names = BTreeSet::new();
    for kind in ["function", "async function", "const", "let", "class"] {
        let marker = format!("export {kind} ");
        for (at, _) in text.match_indices(&marker) {
            let name: String = text[at + marker.len()..]
                .chars()
                .take_while(|&c| part(c))
                .collect();
            names.insert(name);
        }
    }
    names
}

/// The web app's modules tell each other of changes by events (`on`, `emit`), not by
/// importing the module that imports them: its import graph has no circle (it had one of
/// seven modules).
#[test]
fn the_web_apps_modules_import_no_circle() {
    let modules = web_modules();
    let graph: BTreeMap<String, BTreeSet<String>> = modules
        .iter()
        .map(|(name, (_, imports))| {
            let targets = imports.iter().map(|(from, _)| from.clone()).collect();
            (name.clone(), targets)
        })
        .collect();
    assert_eq!(cycle(&graph), None);
}

/// Every name a module of the web app imports is exported by the module it names and used
/// by the importer: a renamed or removed function fails here, not in a user's browser.
#[test]
fn every_name_the_web_app_imports_is_exported_and_used() {
    let modules = web_modules();
    let mut wrong = Vec::new();
    for (name, (text, imports)) in &modules {
        let body: String = text
            .lines()
            .filter(|l| !l.starts_with("import "))
            .collect::<Vec<_>>()
            .join("\n");
        for (from, names) in imports {
            let Some((source, _)) = modules.get(from) else {
                wrong.push(format!("{name} imports from {from}, which is absent"));
                continue;
            };
            for imported in names {
                if !exports(source).contains(imported) {
                    wrong.push(format!(
                        "{name} imports {imported}, which {from} does not export"
                    ));
                }
                if !holds_identifier(&body, imported) {
                    wrong.push(format!("{name} imports {imported} and never uses it"));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The web app's JavaScript passes TypeScript's checker (`tsc` over `// checkJs`, settings
/// in `assets/js/jsconfig.json`): a name no module declares, a call with the wrong number of
/// arguments, a state field the `App` type does not declare, or a DOM property an element
/// lacks fails here. `tsc` comes from Debian's `node-typescript` (installed by `.ci/run`).
#[test]
fn the_web_apps_javascript_passes_the_type_checker() {
    let config = repo().join("coordinator/service/src/web/assets/js/jsconfig.json");
    let output = match std::process::Command::new("tsc")
        .arg("-p")
        .arg(&config)
        .output()
    {
        Ok(output) => output,
        Err(e) => {
            return crate::common::skip(&format!(
                "the type checker `tsc` cannot run ({e}): apt-get install node-typescript"
            ))
        }
    };
    assert!(
        output.status.success(),
        "tsc -p {}:\n{}{}",
        config.display(),
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}
