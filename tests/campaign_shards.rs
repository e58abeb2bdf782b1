//! A campaign split into shards (`sim --shard K/N --json`) and joined (`infotrack merge`)
//! gives the results of the same campaign run in one process.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

mod common;
use common::results_only;

fn infotrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

const CAMPAIGN: [&str; 12] = [
    "sim",
    "--runs",
    "7",
    "--duration",
    "15",
    "--guidance",
    "eer,pfwm,lawn",
    "--motion",
    "cv",
    "--seed",
    "5",
    "--quiet",
];

fn run(args: &[&str], extra: &[&Path]) -> std::process::Output {
    let o = infotrack().args(args).args(extra).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn read(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Runs the campaign's shards K of N, each into `dir/shard-K.json`.
fn shards(dir: &Path, n: u64) -> Vec<PathBuf> {
    (0..n)
        .map(|k| {
            let p = dir.join(format!("shard-{k}.json"));
            let shard = format!("{k}/{n}");
            let mut args = CAMPAIGN.to_vec();
            args.extend(["--shard", shard.as_str(), "--json"]);
            run(&args, &[&p]);
            p
        })
        .collect()
}

#[test]
fn four_shards_merge_to_the_campaign_of_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.json");
    let mut args = CAMPAIGN.to_vec();
    args.push("--json");
    run(&args, &[&one]);
    let parts = shards(dir.path(), 4);
    let part0 = read(&parts[0]);
    assert_eq!(part0["shard"]["count"], 4);
    assert_eq!(
        part0["results"][0]["run_indices"],
        serde_json::json!([0, 4])
    );
    let merged = dir.path().join("merged.json");
    let out = dir.path().join("merged");
    let mut args = vec!["merge"];
    let names: Vec<String> = parts
        .iter()
        .rev()
        .map(|p| p.display().to_string())
        .collect();
    args.extend(names.iter().map(String::as_str));
    args.push("--json");
    let o = run(&args, &[&merged, Path::new("--out"), &out]);
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("n = 7 runs per law"), "{table}");
    let (a, b) = (read(&one), read(&merged));
    assert_eq!(b["merged_from"], 4);
    assert_eq!(results_only(&a), results_only(&b));
    assert!(out.join("report.md").exists() && out.join("metrics.png").exists());
}

#[test]
fn shards_that_are_not_one_campaign_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let parts = shards(dir.path(), 2);
    let merge = |files: &[&Path]| {
        let o = infotrack().arg("merge").args(files).output().unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = merge(&[&parts[0]]);
    assert!(e.contains("shards [1] of 2 are missing"), "{e}");
    let e = merge(&[&parts[0], &parts[0]]);
    assert!(e.contains("shard 0 is also"), "{e}");
    let other = dir.path().join("other.json");
    let mut v = read(&parts[1]);
    v["seed"] = 6.into();
    std::fs::write(&other, v.to_string()).unwrap();
    let e = merge(&[&parts[0], &other]);
    assert!(e.contains("other.json") && e.contains("seed"), "{e}");
    let whole = dir.path().join("whole.json");
    let mut args = CAMPAIGN.to_vec();
    args.push("--json");
    run(&args, &[&whole]);
    let e = merge(&[&whole]);
    assert!(e.contains("whole.json") && e.contains("sim --shard"), "{e}");
    let o = infotrack()
        .args(["sim", "--shard", "4/4"])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("0 <= K < N"), "{e}");
}
