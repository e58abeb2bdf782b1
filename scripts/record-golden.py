#!/usr/bin/env python3
"""Re-record tests/fixtures/golden/ with the current release binary.

The golden tests (tests/golden.rs) prove that a refactor changes nothing. Re-record only
when a change is *meant* to alter the numbers (a new model file, a fixed bug), and put
the largest change this script prints into the commit message: that is the evidence
that the change is what it claims (for example float32 rounding, ~1e-7, not a new
behaviour).

    cargo build --release && python3 scripts/record-golden.py
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "fixtures" / "golden"
BIN = ROOT / "target" / "release" / "infotrack"
METRICS = ["tracking_error_m", "estimation_error_m", "cov_det", "fov_percent"]


def run(args):
    """Runs the binary from the repository root; stops on failure."""
    p = subprocess.run([str(BIN), *args], cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"infotrack {' '.join(args)} failed:\n{p.stdout}\n{p.stderr}")
    return p.stdout


def largest_change(old, new):
    """Largest absolute and relative change over METRICS of two metric dicts."""
    worst = (0.0, 0.0)
    for k in METRICS:
        a, b = float(old[k]), float(new[k])
        if a != a and b != b:  # both NaN
            continue
        d = abs(a - b)
        worst = (max(worst[0], d), max(worst[1], d / max(abs(a), 1e-300)))
    return worst


def record_sim(name):
    """Re-runs the fixture's own command with --json and keeps its 'command' line."""
    path = GOLDEN / f"{name}.json"
    old = json.loads(path.read_text())
    args = old["command"].split()[1:]
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "r.json"
        run([*args, "--quiet", "--json", str(out)])
        new = json.loads(out.read_text())
    # The old file's key order, so the diff shows only what changed.
    new = {"command": old["command"], **{k: new[k] for k in old if k != "command"}, **new}
    worst = (0.0, 0.0)
    for g, n in zip(old["results"], new["results"]):
        for a, b in zip(g["per_run"], n["per_run"]):
            c = largest_change(a, b)
            worst = (max(worst[0], c[0]), max(worst[1], c[1]))
    path.write_text(json.dumps(new, indent=1) + "\n")
    return worst


def record_closed_loop():
    """Re-flies each recorded seed and keeps the summary metrics and the printed row."""
    path = GOLDEN / "closed_loop.json"
    old = json.loads(path.read_text())
    worst = (0.0, 0.0)
    for r in old["runs"]:
        with tempfile.TemporaryDirectory() as d:
            stdout = run(["sim", "--closed-loop", "--seed", str(r["seed"]),
                          "--duration", "30", "--out", d])
            summary = json.loads((Path(d) / "summary.json").read_text())
        lines = stdout.splitlines()
        head = next(i for i, l in enumerate(lines) if l.startswith("|---"))
        metrics = {k: summary[k] for k in METRICS}
        c = largest_change(r["metrics"], metrics)
        worst = (max(worst[0], c[0]), max(worst[1], c[1]))
        r["metrics"], r["table_row"] = metrics, lines[head + 1]
    path.write_text(json.dumps(old, indent=1) + "\n")
    return worst


def main():
    if not BIN.exists():
        sys.exit(f"{BIN} not found: run `cargo build --release` first")
    for name, worst in [("sim", record_sim("sim")),
                        ("sim_vision", record_sim("sim_vision")),
                        ("closed_loop", record_closed_loop())]:
        print(f"{name}: largest change {worst[0]:.3e} absolute, {worst[1]:.3e} relative")


if __name__ == "__main__":
    main()
