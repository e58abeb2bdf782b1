//! The documents a reader reads: a short README, a book (`docs/`, mdBook) whose pages are
//! all in its table of contents and whose links lead somewhere, a benchmark snapshot, and
//! lines short enough to read outside tables and code.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every Markdown page of the book.
fn book_pages() -> Vec<PathBuf> {
    common::markdown_pages(&root().join("docs/src"))
}

/// The documents whose lines a reader reads: README, BENCHMARKS (the book's benchmark
/// page), ARCHITECTURE (the book's architecture page) and every page of the book.
fn read_documents() -> Vec<PathBuf> {
    let mut docs: Vec<PathBuf> = ["README.md", "BENCHMARKS.md", "ARCHITECTURE.md"]
        .iter()
        .map(|f| root().join(f))
        .collect();
    docs.extend(book_pages());
    docs
}

/// The lines of a Markdown text outside fenced code blocks and tables, numbered from 1.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut in_code = false;
    let mut lines = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if !in_code && !line.trim_start().starts_with('|') {
            lines.push((i + 1, line));
        }
    }
    lines
}

#[test]
fn the_readme_is_short() {
    let text = read(&root().join("README.md"));
    let lines = text.lines().count();
    assert!(lines <= 250, "README.md has {lines} lines (at most 250)");
    assert!(
        text.len() <= 20 * 1024,
        "README.md is {} bytes (at most 20 KB)",
        text.len()
    );
}

#[test]
fn the_benchmarks_are_a_snapshot() {
    let text = read(&root().join("BENCHMARKS.md"));
    assert!(
        text.len() <= 30 * 1024,
        "BENCHMARKS.md is {} bytes (at most 30 KB)",
        text.len()
    );
}

#[test]
fn no_line_of_prose_is_longer_than_120_characters() {
    let mut long = Vec::new();
    for doc in read_documents() {
        let text = read(&doc);
        for (n, line) in prose_lines(&text) {
            let width = line.chars().count();
            if width > 120 {
                long.push(format!("{}:{n}: {width} characters", doc.display()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "lines over 120 characters:\n{}",
        long.join("\n")
    );
}

/// The targets of the Markdown links `[text](target)` and mdBook includes in a text,
/// outside code blocks; web and mail links are left out.
fn local_links(text: &str) -> Vec<String> {
    let mut links = Vec::new();
    for (_, line) in prose_lines(text).into_iter().chain(table_lines(text)) {
        for part in line.split("](").skip(1) {
            if let Some(end) = part.find(')') {
                links.push(part[..end].to_string());
            }
        }
        for part in line.split("{{#include ").skip(1) {
            if let Some(end) = part.find("}}") {
                links.push(part[..end].trim().to_string());
            }
        }
    }
    links.retain(|l| !l.starts_with("http") && !l.starts_with("mailto:") && !l.starts_with('#'));
    links
}

/// The table rows of a Markdown text (tables hold links too).
fn table_lines(text: &str) -> Vec<(usize, &str)> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.trim_start().starts_with('|'))
        .map(|(i, l)| (i + 1, l))
        .collect()
}

/// The anchors mdBook gives a page's headings: the heading's text in lower case, spaces
/// as `-`, letters, digits, `-` and `_` kept, everything else dropped.
fn heading_anchors(text: &str) -> Vec<String> {
    prose_lines(text)
        .into_iter()
        .filter_map(|(_, l)| l.strip_prefix('#'))
        .map(|h| {
            let title = h.trim_start_matches('#').trim();
            title
                .chars()
                .filter_map(|c| match c {
                    c if c.is_whitespace() => Some('-'),
                    c if c.is_alphanumeric() || c == '-' || c == '_' => {
                        Some(c.to_lowercase().next().unwrap_or(c))
                    }
                    _ => None,
                })
                .collect()
        })
        .collect()
}

/// A page's text with its mdBook includes in place.
fn with_includes(page: &Path) -> String {
    let text = read(page);
    let dir = page.parent().expect("a page has a folder");
    let mut all = text.clone();
    for link in local_links(&text) {
        if text.contains(&format!("{{{{#include {link}}}}}")) {
            all.push_str(&read(&dir.join(&link)));
        }
    }
    all
}

#[test]
fn every_local_link_leads_to_a_file_and_its_anchor() {
    let mut broken = Vec::new();
    for doc in read_documents() {
        let dir = doc.parent().expect("a document has a folder");
        for link in local_links(&read(&doc)) {
            let (file, anchor) = link.split_once('#').unwrap_or((&link, ""));
            let target = dir.join(file);
            if !target.exists() {
                broken.push(format!("{}: {link}", doc.display()));
            } else if !anchor.is_empty()
                && !heading_anchors(&with_includes(&target))
                    .iter()
                    .any(|a| a == anchor)
            {
                broken.push(format!("{}: {link} (no such heading)", doc.display()));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links to nothing:\n{}",
        broken.join("\n")
    );
}

#[test]
fn anchors_are_made_as_mdbook_makes_them() {
    let page = "# Stop, logs and replay\n## While it tracks\n```sh\n# not a heading\n```\n\
                ## A town from OpenStreetMap\n## `sim --closed-loop`\n";
    assert_eq!(
        heading_anchors(page),
        [
            "stop-logs-and-replay",
            "while-it-tracks",
            "a-town-from-openstreetmap",
            "sim---closed-loop"
        ]
    );
}

#[test]
fn every_page_of_the_book_is_in_its_table_of_contents() {
    let summary = read(&root().join("docs/src/SUMMARY.md"));
    let listed = local_links(&summary);
    let src = root().join("docs/src");
    for page in book_pages() {
        let rel = page.strip_prefix(&src).expect("a page under docs/src");
        let rel = rel.to_string_lossy().replace('\\', "/");
        if rel == "SUMMARY.md" {
            continue;
        }
        assert!(listed.contains(&rel), "docs/src/{rel} is not in SUMMARY.md");
    }
    for page in &listed {
        assert!(
            src.join(page).exists(),
            "SUMMARY.md lists {page}, which is missing"
        );
    }
}

#[test]
fn the_link_check_catches_a_link_to_nothing() {
    let text = "See [the guide](operator/nowhere.md#x) and [web](https://example.org).\n\
                ```sh\n[not a link](in/code.md)\n```\n| a | [row](table.md) |";
    assert_eq!(local_links(text), ["operator/nowhere.md#x", "table.md"]);
}

/// `mdbook build docs`, with mdBook installed into `.deps/mdbook` by
/// `scripts/setup-tests.sh`. Its links and anchors are checked by
/// `every_local_link_leads_to_a_file_and_its_anchor`.
#[test]
fn the_book_builds() {
    let tools = root().join(".deps/mdbook/bin");
    let path = format!(
        "{}:{}",
        tools.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new(tools.join("mdbook"))
        .args(["build", "docs"])
        .current_dir(root())
        .env("PATH", path)
        .output()
        .expect("mdbook runs (scripts/setup-tests.sh installs it into .deps/mdbook)");
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "mdbook build docs failed:\n{log}");
    // With one renderer (HTML) mdBook writes straight into the build folder.
    let index = root().join("target/book/index.html");
    assert!(index.exists(), "{} missing:\n{log}", index.display());
}
