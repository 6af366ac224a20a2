//! The guide a reader starts from: README.md fits on a page, and every relative link of it
//! and of docs/ names a file (or folder) that exists, so a claim's pointer to the test that
//! holds it cannot go stale when a file moves.

use crate::common::*;
use std::path::{Path, PathBuf};

/// README's length: two commands, what it does, where to read on.
const MOST_README_LINES: usize = 150;

/// The relative targets of `[text](target)` links in `text`, without their `#anchor`.
fn relative_links(text: &str) -> Vec<String> {
    let mut links = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        let external = target.contains("://") || target.starts_with("mailto:");
        if !target.is_empty() && !external && !target.contains(' ') {
            links.push(target.to_string());
        }
    }
    links
}

/// README.md and every Markdown file under docs/ and deploy/.
fn guide_pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut pages = vec![repo().join("README.md")];
    walk(&repo().join("docs"), &mut pages);
    walk(&repo().join("deploy"), &mut pages);
    pages
}

#[test]
fn the_reading_finds_relative_links_only() {
    let text = "see [a](docs/a.md#x), [b](https://x.org/y), [c](../c.rs) and [d](#here) [e](f g)";
    assert_eq!(relative_links(text), ["docs/a.md", "../c.rs"]);
}

#[test]
fn the_readme_fits_on_a_page_and_every_link_of_the_guide_resolves() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= MOST_README_LINES,
        "README.md has {lines} lines (at most {MOST_README_LINES}): move detail into docs/"
    );
    let pages = guide_pages();
    assert!(pages.len() > 10, "{} pages found", pages.len());
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for link in relative_links(&text) {
            let target = page.parent().unwrap().join(&link);
            if !target.exists() {
                broken.push(format!(
                    "{}: {link}",
                    page.strip_prefix(repo()).unwrap().display()
                ));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links to nothing:\n{}",
        broken.join("\n")
    );
}
