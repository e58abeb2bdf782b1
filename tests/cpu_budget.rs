//! `scripts/cpu-budget.sh`: a command run inside a cgroup limited to a share of one core
//! (cgroup v2 `cpu.max` or v1 `cpu.cfs_quota_us`), the cgroup removed afterwards.

use std::path::Path;
use std::process::Command;

fn script() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/cpu-budget.sh")
}

#[test]
fn the_command_runs_in_a_cgroup_with_the_quota_asked_for_and_it_is_removed_after() {
    // The command reports its own cgroup and that cgroup's quota.
    let report = r#"
        line=$(grep -E '(^0::|[:,]cpu[,:])' /proc/self/cgroup | grep infotrack-budget | head -1)
        path=${line##*:}
        if [ -f /sys/fs/cgroup$path/cpu.max ]; then cat /sys/fs/cgroup$path/cpu.max
        else cat /sys/fs/cgroup/cpu$path/cpu.cfs_quota_us /sys/fs/cgroup/cpu$path/cpu.cfs_period_us; fi
        echo "$path""#;
    let o = Command::new(script())
        .args(["0.25", "--", "sh", "-c", report])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let words: Vec<&str> = out.split_whitespace().collect();
    assert_eq!(&words[..2], ["25000", "100000"], "{out}");
    let path = words.last().unwrap();
    assert!(path.contains("infotrack-budget-"), "{out}");
    for root in ["/sys/fs/cgroup", "/sys/fs/cgroup/cpu"] {
        assert!(
            !Path::new(&format!("{root}{path}")).exists(),
            "{path} is left behind"
        );
    }
}

#[test]
fn a_share_that_is_not_one_and_the_command_s_failure_are_said() {
    let o = Command::new(script())
        .args(["lots", "--", "true"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2));
    assert!(err.contains("SHARE must be a number of cores"), "{err}");
    let o = Command::new(script())
        .args(["0.5", "--", "sh", "-c", "exit 7"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(7), "the command's own status");
}
