//! Every command the README and the book mark runnable (a fenced block whose info string
//! holds `runnable`, e.g. `sh,runnable`) runs as written on the mock and the simulator.
//! The blocks of one page run in order in one fresh folder, which sees the repository's
//! configs, models, scripts and training code, with this build's `infotrack` first on the
//! PATH; a block fails the test when any of its commands exits non-zero.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The runnable blocks of a Markdown text, each as its lines, in order.
fn runnable_blocks(text: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut current: Option<String> = None;
    for line in text.lines() {
        let fence = line.trim_start();
        match (&mut current, fence.strip_prefix("```")) {
            (None, Some(info)) if info.split(',').any(|w| w.trim() == "runnable") => {
                current = Some(String::new());
            }
            (Some(block), Some(_)) => {
                blocks.push(std::mem::take(block));
                current = None;
            }
            (Some(block), None) => {
                block.push_str(line);
                block.push('\n');
            }
            (None, _) => {}
        }
    }
    blocks
}

/// The documents that may hold runnable commands: README and every page of the book.
fn documents() -> Vec<PathBuf> {
    let mut docs = vec![root().join("README.md")];
    docs.extend(common::markdown_pages(&root().join("docs/src")));
    docs
}

/// A fresh folder that sees what a clone has: configs, models, scripts, training code,
/// firmware parameter files and the installed dependencies.
fn a_clone_like_folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("a temporary folder");
    for entry in [
        "config",
        "models",
        "scripts",
        "training",
        "firmware-params",
        ".deps",
    ] {
        let target = root().join(entry);
        if target.exists() {
            std::os::unix::fs::symlink(&target, dir.path().join(entry)).expect("a symlink");
        }
    }
    dir
}

fn path_with_infotrack_first() -> String {
    let bin = Path::new(env!("CARGO_BIN_EXE_infotrack"));
    let dir = bin.parent().expect("the binary's folder");
    format!(
        "{}:{}",
        dir.display(),
        std::env::var("PATH").unwrap_or_default()
    )
}

/// Runs one page's blocks in order in one folder; returns the failures.
fn run_page(doc: &Path, blocks: &[String]) -> Vec<String> {
    let dir = a_clone_like_folder();
    let mut failures = Vec::new();
    for block in blocks {
        let out = Command::new("bash")
            .args(["-euo", "pipefail", "-c", block])
            .current_dir(dir.path())
            .env("PATH", path_with_infotrack_first())
            .output()
            .expect("bash runs");
        if !out.status.success() {
            failures.push(format!(
                "{}:\n{block}exit {:?}\n{}{}",
                doc.display(),
                out.status.code(),
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
    }
    failures
}

#[test]
fn every_runnable_command_of_the_readme_and_the_book_runs_as_written() {
    let mut ran = 0;
    let mut failures = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).expect("a document reads");
        let blocks = runnable_blocks(&text);
        ran += blocks.len();
        failures.extend(run_page(&doc, &blocks));
    }
    assert!(ran >= 10, "only {ran} runnable blocks found");
    assert!(
        failures.is_empty(),
        "{} blocks failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn only_blocks_marked_runnable_are_taken() {
    let text = "```sh\nnot this\n```\n```sh,runnable\ninfotrack sim \\\n  --runs 1\n```\n\
                ```text\nnor this\n```\n```sh,runnable\nls\n```\n";
    assert_eq!(
        runnable_blocks(text),
        ["infotrack sim \\\n  --runs 1\n", "ls\n"]
    );
}

#[test]
fn a_failing_command_is_reported() {
    let failures = run_page(Path::new("example.md"), &["true\nfalse\n".to_string()]);
    assert_eq!(failures.len(), 1, "{failures:?}");
}
