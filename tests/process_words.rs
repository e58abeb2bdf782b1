//! The product speaks of the product: no source file, script, config, test name or document
//! says which work session, issue or numbered part of the work produced it. History is
//! git's. A domain use (a car's turn, a GCS's session) carries no number and is not caught.
//! The documents (README, BENCHMARKS, the book) also date nothing by a commit: a figure says
//! the day it was measured, not the commit it was measured on.

use std::path::Path;
use std::process::Command;

/// The files checked: every tracked text file of the project's own.
fn tracked_text_files(root: &Path) -> Vec<String> {
    let out = Command::new("git")
        .args(["ls-files"])
        .current_dir(root)
        .output()
        .expect("git lists the tracked files");
    assert!(out.status.success(), "git ls-files failed");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|f| {
            let ext = f.rsplit('.').next().unwrap_or("");
            ["rs", "py", "sh", "toml", "md", "service", "tex", "yaml"].contains(&ext)
        })
        .map(str::to_string)
        .collect()
}

/// A process word (session, part, issue, or their plurals, any case, a possessive too)
/// followed by a number (a `#` before it allowed).
fn process_word_at(line: &str) -> Option<String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    for pair in words.windows(2) {
        let word = pair[0]
            .trim_start_matches(|c: char| !c.is_alphanumeric())
            .to_lowercase();
        let next = pair[1].trim_start_matches('#');
        let numbered = next.chars().next().is_some_and(|c| c.is_ascii_digit());
        let is_word = ["session", "sessions", "part", "parts", "issue", "issues"]
            .contains(&word.trim_end_matches("'s"));
        if is_word && numbered {
            return Some(format!("{} {}", pair[0], pair[1]));
        }
    }
    None
}

#[test]
fn no_file_names_the_session_issue_or_part_that_made_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = tracked_text_files(root);
    assert!(files.len() > 100, "only {} files found", files.len());
    let mut found = Vec::new();
    for f in &files {
        let Ok(text) = std::fs::read_to_string(root.join(f)) else {
            continue;
        };
        for (i, line) in text.lines().enumerate() {
            if let Some(w) = process_word_at(line) {
                found.push(format!("{f}:{}: {w}", i + 1));
            }
        }
    }
    assert!(found.is_empty(), "process words:\n{}", found.join("\n"));
}

#[test]
fn the_check_catches_process_words_and_passes_domain_words() {
    // Built from their parts, so that this file holds no process word itself.
    let caught: Vec<String> = [
        ("before session", "48 the yaw was 0"),
        ("(BENCHMARKS.md part", "42)"),
        ("the fault table of issue", "15"),
        ("see issue", "#16"),
        ("sessions", "18-19 measured it"),
        ("Session", "45's first draw"),
    ]
    .iter()
    .map(|(a, b)| format!("{a} {b}"))
    .collect();
    for line in &caught {
        assert!(process_word_at(line).is_some(), "{line}");
    }
    for passed in [
        "the car's turn at the junction",
        "a GCS session with the pilot",
        "the ort session runs the model",
        "part of the belief",
        "parts per million",
    ] {
        assert_eq!(process_word_at(passed), None, "{passed}");
    }
}

/// A word that looks like an abbreviated commit hash: 7 to 40 hexadecimal digits, at least
/// one a letter and one a digit (so "deadbeef" or "1000000" are not caught). Longer ones
/// are SHA-256 sums of files, which documents may show.
fn commit_hash_in(line: &str) -> Option<String> {
    line.split(|c: char| !c.is_ascii_alphanumeric())
        .find(|w| {
            (7..=40).contains(&w.len())
                && w.chars()
                    .all(|c| c.is_ascii_digit() || ('a'..='f').contains(&c))
                && w.chars().any(|c| c.is_ascii_digit())
                && w.chars().any(|c| c.is_ascii_alphabetic())
        })
        .map(str::to_string)
}

/// The documents a reader reads: README, BENCHMARKS and the book's pages.
fn documents(root: &Path) -> Vec<String> {
    tracked_text_files(root)
        .into_iter()
        .filter(|f| f.ends_with(".md"))
        .filter(|f| !f.contains('/') || f.starts_with("docs/"))
        .collect()
}

#[test]
fn no_document_dates_a_figure_by_a_commit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let docs = documents(root);
    assert!(docs.iter().any(|f| f == "README.md"), "README.md not found");
    assert!(
        docs.iter().any(|f| f.starts_with("docs/src/")),
        "no book pages found"
    );
    let mut found = Vec::new();
    for f in &docs {
        let text = std::fs::read_to_string(root.join(f)).expect("a tracked document reads");
        let mut in_code = false;
        for (i, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                in_code = !in_code;
                continue;
            }
            // Code blocks show what a program prints, commits included.
            if in_code {
                continue;
            }
            if let Some(h) = commit_hash_in(line) {
                found.push(format!("{f}:{}: {h}", i + 1));
            }
        }
    }
    assert!(
        found.is_empty(),
        "commit hashes in documents:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_hash_check_catches_commits_and_passes_numbers_and_words() {
    for caught in ["on main a9fe44a", "(`3fcffaa`)", "built from 64327c3e1af2"] {
        assert!(commit_hash_in(caught).is_some(), "{caught}");
    }
    for passed in [
        "1000000 particles",
        "a deadbeef key",
        "the SHA-256 dbf765e78ad38351e61cc2b36a7adcdb3981576cc67730eb0c83417729bb8f88",
        "decade",
    ] {
        assert_eq!(commit_hash_in(passed), None, "{passed}");
    }
}
