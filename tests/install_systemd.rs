//! The one-command install on a machine with systemd running, for real: systemd is booted as
//! PID 1 of its own namespaces on a copy-on-write overlay of this machine's root
//! (`tests/systemd/boot.sh`), `scripts/install.sh` installs there as an operator would, and
//! `systemctl start infotrack` starts the installed unit. The unit must run as the user
//! `infotrack`, fly (the lab config, whose vehicle is the in-process mock), log to the journal
//! at RUST_LOG's level without colour codes, stop on `systemctl stop` with the vehicle in
//! hold, and leave the flight's logs under /var/lib/infotrack/flights. Nothing is written to
//! the real root: every file lands in the overlay's upper folder, which the test reads.
//!
//! Needs root (namespaces, mounts), as `scripts/test.sh` has on the machines it is for; without
//! it the test fails and says so.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// systemd booted in its own namespaces; killed (and its whole PID namespace with it) on drop.
struct Machine {
    unshare: Child,
    systemd_pid: u32,
    dir: tempfile::TempDir,
}

impl Drop for Machine {
    fn drop(&mut self) {
        // SAFETY: kill only sends a signal; PID 1 of a namespace dies only of SIGKILL from
        // outside, and every process of the namespace with it.
        unsafe {
            libc::kill(self.systemd_pid as i32, libc::SIGKILL);
        }
        let _ = self.unshare.wait();
    }
}

impl Machine {
    /// This machine's own root, booted.
    fn boot() -> Self {
        Self::boot_root(Path::new("/"), 60)
    }

    /// `lower` booted as the machine's root, running within `secs` seconds.
    fn boot_root(lower: &Path, secs: u64) -> Self {
        // SAFETY: geteuid has no preconditions.
        let uid = unsafe { libc::geteuid() };
        assert_eq!(
            uid, 0,
            "this test boots systemd in its own namespaces and needs root (scripts/test.sh runs as root on the machines it is for)"
        );
        let project = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let dir = tempfile::Builder::new()
            .prefix("infotrack-systemd-")
            .tempdir_in("/var/tmp")
            .unwrap();
        let console = std::fs::File::create(dir.path().join("console.log")).unwrap();
        let unshare = Command::new("unshare")
            .args([
                "--pid",
                "--fork",
                "--mount",
                "--mount-proc",
                "--propagation",
                "private",
                "bash",
            ])
            .arg(project.join("tests/systemd/boot.sh"))
            .arg(dir.path().join("root"))
            .arg(&project)
            .arg(lower)
            // qemu-user would look up the machine's paths under this prefix first.
            .env_remove("QEMU_LD_PREFIX")
            .stdout(Stdio::from(console.try_clone().unwrap()))
            .stderr(Stdio::from(console))
            .spawn()
            .unwrap();
        let pid = unshare.id();
        let until = Instant::now() + Duration::from_secs(secs);
        let systemd_pid = loop {
            let children = std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
                .unwrap_or_default();
            let found = children.split_whitespace().find_map(|c| {
                let comm = std::fs::read_to_string(format!("/proc/{c}/comm")).ok()?;
                (comm.trim() == "systemd")
                    .then(|| c.parse::<u32>().ok())
                    .flatten()
            });
            if let Some(p) = found {
                break p;
            }
            assert!(
                Instant::now() < until,
                "systemd did not start in its namespace within {secs} s; console:\n{}",
                std::fs::read_to_string(dir.path().join("console.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(200));
        };
        let m = Machine {
            unshare,
            systemd_pid,
            dir,
        };
        m.wait_for("systemd running", secs, || {
            let (_, out) = m.sh("systemctl is-system-running");
            matches!(out.trim(), "running" | "degraded")
        });
        m
    }

    /// Runs `script` with bash inside the machine (its mounts, PIDs, root and working
    /// folder); its exit status and what it printed.
    fn sh(&self, script: &str) -> (bool, String) {
        let o = Command::new("nsenter")
            .args(["-t", &self.systemd_pid.to_string(), "-m", "-p", "-r", "-w"])
            .args(["bash", "-c", script])
            .env_remove("QEMU_LD_PREFIX")
            .output()
            .unwrap();
        (
            o.status.success(),
            format!(
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            ),
        )
    }

    fn must(&self, script: &str) -> String {
        let (ok, out) = self.sh(script);
        assert!(ok, "`{script}` failed in the booted machine:\n{out}");
        out
    }

    fn wait_for(&self, what: &str, secs: u64, mut done: impl FnMut() -> bool) {
        let until = Instant::now() + Duration::from_secs(secs);
        while !done() {
            assert!(
                Instant::now() < until,
                "{what}: not within {secs} s; journal:\n{}",
                self.sh("journalctl --no-pager -n 60").1
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }

    /// A path of the machine's root as written by it (the overlay's upper folder).
    fn written(&self, path: &str) -> PathBuf {
        self.dir
            .path()
            .join("root/upper")
            .join(path.trim_start_matches('/'))
    }
}

fn journal(m: &Machine) -> String {
    m.sh("journalctl -u infotrack -o cat --no-pager").1
}

#[test]
fn the_installed_unit_starts_flies_the_mock_as_its_user_and_keeps_its_logs() {
    let m = Machine::boot();
    let project = env!("CARGO_MANIFEST_DIR");
    let binary = env!("CARGO_BIN_EXE_infotrack");
    assert!(
        Path::new(binary).starts_with(project),
        "the test binary {binary} must be inside the project (bound into the machine)"
    );
    // The one command, with the lab config (its vehicle is the in-process mock).
    let said = m.must(&format!(
        "cd {project} && bash scripts/install.sh --binary {binary} --config default.toml"
    ));
    assert!(said.contains("systemctl enable --now infotrack"), "{said}");
    m.must("systemctl start infotrack");
    m.wait_for("the unit tracking", 90, || {
        journal(&m).contains("infotrack: tracking started")
    });
    let user = m.must("ps -o user:20= -C infotrack");
    assert_eq!(
        user.trim(),
        "infotrack",
        "the daemon runs as `{}`",
        user.trim()
    );
    std::thread::sleep(Duration::from_secs(5));
    m.must("systemctl stop infotrack");
    let (_, state) = m.sh("systemctl is-active infotrack");
    assert_eq!(state.trim(), "inactive", "after systemctl stop");
    let status = m.must("systemctl show -p ExecMainStatus --value infotrack");
    assert_eq!(status.trim(), "0", "the daemon's exit status");

    let j = journal(&m);
    println!("journal of the unit:\n{j}");
    // RUST_LOG=info from the unit is honoured (the unit passes no --log), plain text.
    assert!(
        j.contains(" INFO "),
        "no INFO lines: RUST_LOG ignored?\n{j}"
    );
    assert!(!j.contains('\u{1b}'), "colour codes in the journal\n{j}");
    assert!(j.contains("ended in HOLD"), "{j}");

    // The flight's logs, in one folder under /var/lib/infotrack/flights, owned by the user.
    let flights = m.written("/var/lib/infotrack/flights");
    let folders: Vec<PathBuf> = std::fs::read_dir(&flights)
        .unwrap_or_else(|e| panic!("{}: {e}", flights.display()))
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(folders.len(), 1, "{folders:?}");
    for f in ["summary.json", "flight.csv", "steps.csv", "link.tlog"] {
        assert!(
            folders[0].join(f).is_file(),
            "{f} missing in {:?}",
            folders[0]
        );
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folders[0].join("summary.json")).unwrap())
            .unwrap();
    let tracking = summary["tracking_error_m"].as_f64();
    assert!(
        tracking.is_some_and(f64::is_finite),
        "summary.json has no tracking error: {summary}"
    );
    let owner = m.must(&format!(
        "stat -c %U /var/lib/infotrack/flights/{}/summary.json",
        folders[0].file_name().unwrap().to_string_lossy()
    ));
    assert_eq!(owner.trim(), "infotrack");
}

/// `scripts/build-deb.sh` for the test binary, into the project's `target/` (bound into
/// the machine); the package's path.
fn build_deb(version: &str) -> String {
    let project = env!("CARGO_MANIFEST_DIR");
    let out = Command::new("bash")
        .arg(format!("{project}/scripts/build-deb.sh"))
        .args(["--fast", "--binary", env!("CARGO_BIN_EXE_infotrack")])
        .args(["--version", version, "--out"])
        .arg(format!("{project}/target/debian-test"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "build-deb.sh: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

#[test]
fn the_debian_package_installs_flies_upgrades_and_removes_cleanly() {
    let version = env!("CARGO_PKG_VERSION");
    let (first, next) = (build_deb(version), build_deb(&format!("{version}+1")));
    let m = Machine::boot();
    install_fly_upgrade_remove(&m, &format!("dpkg -i {first}"), &next, version);
}

/// The arm64 package without OpenCV (`scripts/build-arm64.sh --no-opencv --test --deb` builds
/// it and runs this test; the one with OpenCV needs arm64 OpenCV, which cannot be installed
/// beside this machine's amd64 one: it is installed on a booted arm64 Debian 12, below),
/// installed with dpkg beside the machine's arm64 libraries (multiarch), its program run by
/// qemu-user through the kernel's binfmt_misc handler as a board would run it natively.
/// ONNX Runtime reads the CPU's description from /proc/cpuinfo, which emulation leaves the
/// host's: the machine sees a Cortex-A72's (a Raspberry Pi 4's core).
#[test]
#[ignore = "needs the arm64 packages: run by scripts/build-arm64.sh --no-opencv --test --deb"]
fn the_arm64_package_installs_flies_upgrades_and_removes_cleanly_under_emulation() {
    let deb = |var: &str| {
        std::env::var(var).unwrap_or_else(|_| panic!("{var}: the arm64 package's path"))
    };
    let (first, next) = (deb("INFOTRACK_ARM64_DEB"), deb("INFOTRACK_ARM64_DEB_NEXT"));
    let version = env!("CARGO_PKG_VERSION");
    let m = Machine::boot();
    let handler = Arm64Handler::register(&m);
    show_a_cortex_a72(&m);
    install_fly_upgrade_remove(&m, &format!("dpkg -i {first}"), &next, version);
    let arch = m.must(&format!("dpkg-deb -f {first} Architecture"));
    assert_eq!(arch.trim(), "arm64");
    drop(handler);
}

/// The arm64 package with OpenCV on an arm64 Debian 12 booted as a board boots: its own
/// systemd as PID 1, every program of it (systemd, dpkg, apt, the maintainer scripts,
/// infotrack) run by qemu-user-static through the kernel's binfmt_misc handler.
/// `scripts/build-arm64.sh --test --deb` (or `--deb --board`) makes the root (systemd and the package's
/// dependencies, systemd-binfmt masked so that its boot leaves the handler in place),
/// registers the handler, and runs this test. `apt install` then installs the package as
/// the docs say, and the unit flies, is upgraded, removed and purged.
#[test]
#[ignore = "needs an arm64 Debian 12 root: run by scripts/build-arm64.sh --test --deb"]
fn the_arm64_package_installs_flies_upgrades_and_removes_cleanly_on_a_booted_arm64_debian() {
    let var = |v: &str| std::env::var(v).unwrap_or_else(|_| panic!("{v} is not set"));
    let (root, first, next) = (
        var("INFOTRACK_ARM64_BOARD_ROOT"),
        var("INFOTRACK_ARM64_DEB"),
        var("INFOTRACK_ARM64_DEB_NEXT"),
    );
    let handler = std::fs::read_to_string(Arm64Handler::ENTRY).unwrap_or_default();
    assert!(
        handler.contains("qemu-aarch64-static") && handler.contains("flags: F"),
        "the arm64 root's programs need qemu-aarch64-static registered with flag F at {}:\n{handler}",
        Arm64Handler::ENTRY
    );
    let m = Machine::boot_root(Path::new(&root), 300);
    assert_eq!(m.must("uname -m").trim(), "aarch64", "the booted machine");
    show_a_cortex_a72(&m);
    let version = env!("CARGO_PKG_VERSION");
    let install = format!("DEBIAN_FRONTEND=noninteractive apt-get install -y -q {first}");
    install_fly_upgrade_remove(&m, &install, &next, version);
    let linked = m.must("dpkg -s libopencv-core406 | sed -n 's/^Architecture: //p'");
    assert_eq!(linked.trim(), "arm64", "the board's OpenCV");
}

/// The machine's /proc/cpuinfo made a Raspberry Pi 4's, for ONNX Runtime (emulation leaves
/// the host's).
fn show_a_cortex_a72(m: &Machine) {
    m.must(&format!(
        "printf '%s' '{CORTEX_A72_CPUINFO}' > /var/tmp/cpuinfo-a72"
    ));
    m.must("mount --bind /var/tmp/cpuinfo-a72 /proc/cpuinfo");
}

/// /proc/cpuinfo of a Raspberry Pi 4 (one Cortex-A72 core is enough for ONNX Runtime).
const CORTEX_A72_CPUINFO: &str = "processor\t: 0\nBogoMIPS\t: 108.00\nFeatures\t: fp asimd evtstrm crc32 cpuid\nCPU implementer\t: 0x41\nCPU architecture: 8\nCPU variant\t: 0x0\nCPU part\t: 0xd08\nCPU revision\t: 3\n";

/// qemu-aarch64 registered with the kernel as the handler of arm64 programs (flag F: the
/// kernel holds the interpreter open, so it works in any root); unregistered on drop if this
/// registered it. Registered from inside the machine, after its boot (systemd-binfmt
/// flushes the handlers when it starts).
struct Arm64Handler<'a> {
    machine: &'a Machine,
    registered_here: bool,
}

impl<'a> Arm64Handler<'a> {
    const ENTRY: &'static str = "/proc/sys/fs/binfmt_misc/qemu-aarch64";

    fn register(m: &'a Machine) -> Self {
        m.must("mountpoint -q /proc/sys/fs/binfmt_misc || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc");
        if m.sh(&format!("test -e {}", Self::ENTRY)).0 {
            return Self {
                machine: m,
                registered_here: false,
            };
        }
        let magic = r"\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\xb7\x00";
        let mask =
            r"\xff\xff\xff\xff\xff\xff\xff\x00\xff\xff\xff\xff\xff\xff\xff\xff\xfe\xff\xff\xff";
        m.must(&format!(
            "printf '%s' ':qemu-aarch64:M::{magic}:{mask}:/usr/bin/qemu-aarch64:F' > /proc/sys/fs/binfmt_misc/register"
        ));
        Self {
            machine: m,
            registered_here: true,
        }
    }
}

impl Drop for Arm64Handler<'_> {
    fn drop(&mut self) {
        if self.registered_here {
            let _ = self.machine.sh(&format!("echo -1 > {}", Self::ENTRY));
        }
    }
}

/// `install` (the first package's install command), the unit flying the lab, an upgrade to
/// `next` that keeps an edited conffile, then `dpkg -r` and `dpkg -P`.
fn install_fly_upgrade_remove(m: &Machine, install: &str, next: &str, version: &str) {
    m.must(install);
    let said =
        m.must("infotrack --version; id -nG infotrack; stat -c %U /var/lib/infotrack/flights");
    assert!(said.contains(&format!("infotrack {version} (")), "{said}");
    assert!(
        said.contains("infotrack") && said.contains("dialout"),
        "{said}"
    );
    // The unit flies the lab (its vehicle the in-process mock): an operator's drop-in.
    m.must(
        "mkdir -p /etc/systemd/system/infotrack.service.d && printf '[Service]\\nExecStart=\\nExecStart=/usr/bin/infotrack run --config /etc/infotrack/config/default.toml --duration 0 --quiet --log-dir /var/lib/infotrack/flights\\n' > /etc/systemd/system/infotrack.service.d/lab.conf && systemctl daemon-reload && systemctl start infotrack",
    );
    m.wait_for("the packaged unit tracking", 240, || {
        journal(m).contains("infotrack: tracking started")
    });
    m.must("systemctl stop infotrack");
    assert!(journal(m).contains("ended in HOLD"), "{}", journal(m));
    // An upgrade keeps the operator's edit of a conffile.
    m.must("echo '# the operator was here' >> /etc/infotrack/config/px4.toml");
    m.must(&format!("dpkg -i --force-confold {next}"));
    let said =
        m.must("dpkg-query -W -f '${Version}' infotrack; tail -1 /etc/infotrack/config/px4.toml");
    assert!(said.starts_with(&format!("{version}+1")), "{said}");
    assert!(said.contains("the operator was here"), "{said}");
    // Removed: the program goes, the configs and logs stay; purged: everything, the user too.
    m.must("dpkg -r infotrack");
    let (gone, _) = m.sh("test -e /usr/lib/infotrack/infotrack || test -e /usr/bin/infotrack");
    assert!(!gone, "the program is left after dpkg -r");
    m.must("test -f /etc/infotrack/config/px4.toml && test -d /var/lib/infotrack/flights");
    m.must("dpkg -P infotrack");
    m.must(
        "! test -e /etc/infotrack && ! test -e /var/lib/infotrack && ! id infotrack 2>/dev/null",
    );
}
