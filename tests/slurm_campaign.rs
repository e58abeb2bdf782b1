//! A campaign on a real Slurm: a one-node cluster started for the test
//! (`scripts/slurm-local.sh`, Debian's slurm-wlm and munge, as root), the campaign submitted
//! as an array job of shards and a merge job (`scripts/slurm-campaign.sh`), and the merged
//! result compared with the same campaign run in one process.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

mod common;
use common::results_only;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Stops the cluster however the test ends.
struct Cluster(std::path::PathBuf);

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(root().join("scripts/slurm-local.sh"))
            .arg("stop")
            .arg(&self.0)
            .status();
    }
}

fn check(o: std::process::Output, what: &str) -> String {
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{what}: {text}");
    text
}

#[test]
fn a_slurm_array_campaign_merges_to_the_one_process_result() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = Cluster(dir.path().join("slurm"));
    check(
        Command::new("timeout")
            .arg("90")
            .arg(root().join("scripts/slurm-local.sh"))
            .arg("start")
            .arg(&cluster.0)
            .output()
            .unwrap(),
        "starting the one-node Slurm (root, slurm-wlm and munge: scripts/setup-tests.sh)",
    );
    let sim = [
        "--runs",
        "10",
        "--duration",
        "15",
        "--guidance",
        "eer,pfwm,lawn",
        "--seed",
        "3",
    ];
    let campaign = dir.path().join("campaign");
    let said = check(
        Command::new("timeout")
            .arg("300")
            .arg(root().join("scripts/slurm-campaign.sh"))
            .args(["--shards", "5", "--wait", "--dir"])
            .arg(&campaign)
            .arg("--infotrack")
            .arg(env!("CARGO_BIN_EXE_infotrack"))
            .arg("--")
            .args(sim)
            .env("SLURM_CONF", cluster.0.join("slurm.conf"))
            .output()
            .unwrap(),
        "the campaign on Slurm",
    );
    assert!(said.contains("array 0-4"), "{said}");
    let one = dir.path().join("one.json");
    check(
        Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .arg("sim")
            .args(sim)
            .args(["--quiet", "--json"])
            .arg(&one)
            .output()
            .unwrap(),
        "the campaign in one process",
    );
    let read =
        |p: &Path| -> Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let merged = read(&campaign.join("results.json"));
    assert_eq!(merged["merged_from"], 5);
    assert_eq!(results_only(&merged), results_only(&read(&one)));
    let table = std::fs::read_to_string(campaign.join("merge.log")).unwrap();
    assert!(table.contains("n = 10 runs per law"), "{table}");
    assert!(campaign.join("report.md").exists());
}
