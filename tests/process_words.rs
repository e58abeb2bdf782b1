//! The product speaks of the product: no source file, script, config, test name or document
//! says which work session, issue or numbered part of the work produced it. History is
//! git's. A domain use (a car's turn, a GCS's session) carries no number and is not caught.

use std::path::Path;
use std::process::Command;

/// Documents still written as a log of the work, to be rewritten as pages of the book; each
/// is checked once it is. Nothing else is skipped.
const NOT_YET_REWRITTEN: [&str; 2] = ["README.md", "BENCHMARKS.md"];

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
        .filter(|f| !NOT_YET_REWRITTEN.contains(f))
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
