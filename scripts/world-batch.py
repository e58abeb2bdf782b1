#!/usr/bin/env python3
"""Measure a build on the field worlds nobody tuned to, and compare two such measurements.

    python3 scripts/world-batch.py run --bin target/release/infotrack --out DIR [--seed S]
        [--set random|stand-ins|all] [--jobs 2] [--guidance eer] [--motion cv] [--runs 10]
        [--duration SECONDS] [--key SECTION.KEY=VALUE ...] [--scale SECTION.KEY=FACTOR ...]
    python3 scripts/world-batch.py compare DIR_A DIR_B

The field-scale target (EER keeps the target in view >= 60 % of the time with a mean
tracking error <= 20 m, on a field world we have not seen, `--motion cv`) is estimated since
BENCHMARKS.md on two sets of worlds:

* `random`: sixteen worlds drawn by `scripts/random-world.py` (seeds 1-8 with two-way share
  0.5 and `--orientation random`, seeds 11-18 with one-way streets), written to DIR/worlds;
* `stand-ins`: the hand-written `config/field-*.toml`.

`run` flies `infotrack sim --config W --runs 10 --guidance eer --motion cv --quiet --threads 1
--json ...` on every world, `--jobs` at a time (each single-threaded, so a batch's figures do
not depend on how many run beside it), each on the world's own seed or on `--seed`. It
writes DIR/summary.json (the figures per world, with each run's) and prints a table: per
world the mean %FOV and tracking error, how many runs never saw the target and the tracking
error after the first sighting (the search apart from the tracking; BENCHMARKS.md),
then the mean %FOV over the set and on how many worlds both targets hold.

`--key guidance.view_heading='"informed"'` (repeatable; the value is written as TOML, so a
string keeps its quotes) flies a copy of every world, written to DIR/worlds, with that key set:
a config variant measured on the same worlds and seeds as its base, with no scratch build. A
key the world already sets is refused, so a variant never silently replaces a world's value.

`--scale agent.accel_limit_mps2=2` (repeatable) multiplies a number every world sets by the
factor, in a copy written to DIR/worlds: a diagnostic of what a world's own setting decides
(BENCHMARKS.md doubled the drone's acceleration by hand), not a variant of the
product. A world that does not set the key, or sets it to something other than one number,
is refused, naming the world.

`compare` pairs two summaries world by world (a change measured against its base, both run
with the same seed): the %FOV difference's mean and paired t statistic, and the worlds on
which both targets hold in each. With 10 runs a single world's mean FOV moves by 4-13 points
from noise alone (BENCHMARKS.md), so judge a change by the paired figures over a set,
and on more than one seed.
"""

import argparse
import concurrent.futures
import json
import math
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent

# The sixteen random worlds of BENCHMARKS.md: (name, random-world.py arguments).
RANDOM_WORLDS = [(f"random-{s}", [str(s), "0.5", "--orientation", "random"]) for s in range(1, 9)] + [
    (f"random-{s}", [str(s), "0"]) for s in range(11, 19)
]

# The field-scale targets for a field world.
FOV_TARGET_PERCENT = 60.0
TRACKING_TARGET_M = 20.0


def draw_random_worlds(worlds_dir):
    """Write the sixteen random worlds into `worlds_dir`; returns [(name, path)]."""
    worlds_dir.mkdir(parents=True, exist_ok=True)
    out = []
    for name, args in RANDOM_WORLDS:
        text = subprocess.run(
            [sys.executable, str(ROOT / "scripts" / "random-world.py"), *args],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
        path = worlds_dir / f"{name}.toml"
        path.write_text(text)
        out.append((name, path))
    return out


def stand_in_worlds():
    """The hand-written field worlds, [(name, path)]."""
    return [(p.stem, p) for p in sorted((ROOT / "config").glob("field-*.toml"))]


def parse_key(text):
    """`SECTION.KEY=VALUE` (the section may be dotted: `guidance.lawn.x=1`) -> (section, key,
    value); exits naming the argument when it is not of that form."""
    path, sep, value = text.partition("=")
    section, dot, key = path.strip().rpartition(".")
    if not (sep and dot and section and key and value.strip()):
        sys.exit(f"--key {text!r}: expected SECTION.KEY=VALUE, e.g. guidance.intercept_within_s=10")
    return section, key.strip(), value.strip()


def section_and_key(lines, section, key):
    """Where `[section]` starts in the world's `lines` and the line inside it that sets `key`;
    either None when absent."""
    header = f"[{section}]"
    start = next((i for i, l in enumerate(lines) if l.strip() == header), None)
    if start is None:
        return None, None
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    at = next((i for i in range(start + 1, end) if lines[i].split("=")[0].strip() == key and "=" in lines[i]), None)
    return start, at


def with_keys(name, text, keys):
    """The world's TOML text with each (section, key, value) set: inserted under the section's
    header, or the section appended when the world has none. Exits when the world already sets
    the key (a variant must not silently replace a world's own value)."""
    lines = text.splitlines()
    for section, key, value in keys:
        start, at = section_and_key(lines, section, key)
        if start is None:
            lines += ["", f"[{section}]", f"{key} = {value}"]
            continue
        if at is not None:
            sys.exit(f"--key {section}.{key}: world {name} already sets it")
        lines.insert(start + 1, f"{key} = {value}")
    return "\n".join(lines) + "\n"


def parse_scale(text):
    """`SECTION.KEY=FACTOR` -> (section, key, factor); exits naming the argument when it is
    not of that form or the factor is not a finite number."""
    section, key, value = parse_key(text)
    try:
        factor = float(value)
    except ValueError:
        factor = math.nan
    if not math.isfinite(factor):
        sys.exit(f"--scale {text!r}: expected SECTION.KEY=FACTOR with a number, e.g. agent.accel_limit_mps2=2")
    return section, key, factor


def with_scales(name, text, scales):
    """The world's TOML text with each (section, key, factor)'s number multiplied by the
    factor. Exits when the world does not set the key to one number."""
    lines = text.splitlines()
    for section, key, factor in scales:
        _, at = section_and_key(lines, section, key)
        if at is None:
            sys.exit(f"--scale {section}.{key}: world {name} does not set it")
        value = lines[at].split("=", 1)[1].split("#")[0].strip()
        try:
            number = float(value)
        except ValueError:
            sys.exit(f"--scale {section}.{key}: world {name} sets it to {value!r}, not one number")
        lines[at] = f"{key} = {number * factor!r}"
    return "\n".join(lines) + "\n"


def apply_keys(worlds, worlds_dir, keys, scales=()):
    """Copies of `worlds` with `keys` set, written to `worlds_dir`; returns [(name, path)]."""
    if not keys and not scales:
        return worlds
    worlds_dir.mkdir(parents=True, exist_ok=True)
    out = []
    for name, path in worlds:
        copy = worlds_dir / f"{name}.toml"
        text = with_keys(name, pathlib.Path(path).read_text(), keys)
        copy.write_text(with_scales(name, text, scales))
        out.append((name, copy))
    return out


def fly(binary, name, config, json_path, args):
    """One world's batch; returns (name, its summary row) or raises with the command's error."""
    cmd = [
        str(binary),
        "sim",
        "--config",
        str(config),
        "--runs",
        str(args.runs),
        "--guidance",
        args.guidance,
        "--motion",
        args.motion,
        "--quiet",
        "--threads",
        "1",
        "--json",
        str(json_path),
    ]
    if args.seed is not None:
        cmd += ["--seed", str(args.seed)]
    if args.duration is not None:
        cmd += ["--duration", str(args.duration)]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{name}: `{' '.join(cmd)}` failed ({done.returncode}):\n{done.stderr}")
    results = json.loads(json_path.read_text())["results"]
    row = next(
        (r for r in results if r["guidance"] == args.guidance and r["motion"] == args.motion),
        None,
    )
    if row is None:
        raise RuntimeError(f"{name}: no {args.guidance}/{args.motion} row in {json_path}")
    summary = {
        "config": str(config),
        "fov_percent": row["fov_percent"]["mean"],
        "tracking_error_m": row["tracking_error_m"]["mean"],
        "per_run_fov_percent": [r["fov_percent"] for r in row["per_run"]],
        "per_run_tracking_error_m": [r["tracking_error_m"] for r in row["per_run"]],
    }
    # The search apart from the tracking, from binaries that write it.
    if all("first_sighting_s" in r for r in row["per_run"]):
        summary["per_run_first_sighting_s"] = [r["first_sighting_s"] for r in row["per_run"]]
        summary["per_run_tracking_error_after_first_sighting_m"] = [
            r["tracking_error_after_first_sighting_m"] for r in row["per_run"]
        ]
    return name, summary


def never_seen(row):
    """Runs that never saw the target; None for a summary from an older binary."""
    firsts = row.get("per_run_first_sighting_s")
    return None if firsts is None else sum(f is None for f in firsts)


def tracking_after_first_sighting(row):
    """Mean over the runs that saw the target of their tracking error from then on, m; None
    when no run saw it or the summary is from an older binary."""
    after = [e for e in row.get("per_run_tracking_error_after_first_sighting_m") or [] if e is not None]
    return sum(after) / len(after) if after else None


def meets_targets(row):
    return row["fov_percent"] >= FOV_TARGET_PERCENT and row["tracking_error_m"] <= TRACKING_TARGET_M


def run(args):
    out = pathlib.Path(args.out).resolve()
    binary = pathlib.Path(args.bin).resolve()
    if not binary.is_file():
        sys.exit(f"--bin {args.bin}: no such file (build it first: cargo build --release)")
    worlds = []
    if args.set in ("random", "all"):
        worlds += draw_random_worlds(out / "worlds")
    if args.set in ("stand-ins", "all"):
        worlds += stand_in_worlds()
    worlds = apply_keys(
        worlds, out / "worlds", [parse_key(k) for k in args.key], [parse_scale(k) for k in args.scale]
    )
    (out / "json").mkdir(parents=True, exist_ok=True)
    rows = {}
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = [
            pool.submit(fly, binary, name, path, out / "json" / f"{name}.json", args)
            for name, path in worlds
        ]
        for f in concurrent.futures.as_completed(futures):
            try:
                name, row = f.result()
            except RuntimeError as e:
                pool.shutdown(wait=False, cancel_futures=True)
                sys.exit(str(e))
            rows[name] = row
            print(f"  {name}: {row['fov_percent']:.1f} % / {row['tracking_error_m']:.1f} m", flush=True)
    ordered = {name: rows[name] for name, _ in worlds}
    summary = {
        "binary": str(binary),
        "seed": args.seed,
        "guidance": args.guidance,
        "motion": args.motion,
        "runs": args.runs,
        "duration_s": args.duration,
        "keys": args.key,
        "scales": args.scale,
        "worlds": ordered,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print_table(ordered)
    print(f"wrote {out / 'summary.json'}")


def print_table(rows):
    print(f"{'world':14s} {'%FOV':>6s} {'track (m)':>10s}  both targets  never seen  after 1st (m)")
    for name, r in rows.items():
        mark = "yes" if meets_targets(r) else "no"
        print(
            f"{name:14s} {r['fov_percent']:6.1f} {r['tracking_error_m']:10.1f}  {mark:12s}  "
            f"{optional(never_seen(r), '{:d}'):>10s}  {optional(tracking_after_first_sighting(r), '{:.1f}'):>13s}"
        )
    random = {k: r for k, r in rows.items() if k.startswith("random-")}
    stand_ins = {k: r for k, r in rows.items() if not k.startswith("random-")}
    if random and stand_ins:
        print_set_line("random worlds: ", random)
        print_set_line("stand-ins: ", stand_ins)
    print_set_line("", rows)


def optional(value, fmt):
    return "-" if value is None else fmt.format(value)


def print_set_line(label, rows):
    n = len(rows)
    if n:
        mean = sum(r["fov_percent"] for r in rows.values()) / n
        both = sum(meets_targets(r) for r in rows.values())
        never = [never_seen(r) for r in rows.values()]
        runs = "" if None in never else f"; never seen in {sum(never)} runs"
        print(f"{label}mean %FOV {mean:.2f} over {n} worlds; both targets on {both} of {n}{runs}")


def paired_t(diffs):
    """Mean of `diffs` and its paired t statistic (0 when undefined)."""
    n = len(diffs)
    mean = sum(diffs) / n
    if n < 2:
        return mean, 0.0
    sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (n - 1))
    return mean, (mean / (sd / math.sqrt(n)) if sd > 0 else 0.0)


def compare(args):
    a = json.loads((pathlib.Path(args.a) / "summary.json").read_text())["worlds"]
    b = json.loads((pathlib.Path(args.b) / "summary.json").read_text())["worlds"]
    common = [name for name in a if name in b]
    if not common:
        sys.exit(f"{args.a} and {args.b} share no world")
    for name in common:
        ra, rb = a[name], b[name]
        print(
            f"{name:14s} {ra['fov_percent']:5.1f} / {ra['tracking_error_m']:6.1f} m -> "
            f"{rb['fov_percent']:5.1f} / {rb['tracking_error_m']:6.1f} m"
        )
    random = [n for n in common if n.startswith("random-")]
    stand_ins = [n for n in common if not n.startswith("random-")]
    if random and stand_ins:
        print_paired_line("random worlds: ", a, b, random)
        print_paired_line("stand-ins: ", a, b, stand_ins)
    print_paired_line("", a, b, common)


def print_paired_line(label, a, b, names):
    diffs = [b[n]["fov_percent"] - a[n]["fov_percent"] for n in names]
    mean, t = paired_t(diffs)
    mean_a = sum(a[n]["fov_percent"] for n in names) / len(names)
    mean_b = sum(b[n]["fov_percent"] for n in names) / len(names)
    both_a = sum(meets_targets(a[n]) for n in names)
    both_b = sum(meets_targets(b[n]) for n in names)
    never_a = [never_seen(a[n]) for n in names]
    never_b = [never_seen(b[n]) for n in names]
    runs = "" if None in never_a + never_b else f"; never seen in {sum(never_a)} -> {sum(never_b)} runs"
    print(
        f"{label}mean %FOV {mean_a:.2f} -> {mean_b:.2f} (paired {mean:+.2f} points, t {t:.2f}); "
        f"both targets on {both_a} -> {both_b} of {len(names)}{runs}"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="measure a build on the worlds")
    r.add_argument("--bin", required=True, help="the infotrack binary to measure")
    r.add_argument("--out", required=True, help="directory for the worlds, each batch's JSON and summary.json")
    r.add_argument("--set", choices=["random", "stand-ins", "all"], default="all")
    r.add_argument("--seed", type=int, default=None, help="one seed for every world (default: each world's own)")
    r.add_argument("--jobs", type=int, default=2, help="worlds flown at a time (each single-threaded)")
    r.add_argument("--runs", type=int, default=10)
    r.add_argument("--duration", type=float, default=None, help="seconds per run (default: each world's)")
    r.add_argument("--guidance", default="eer")
    r.add_argument("--motion", default="cv")
    r.add_argument(
        "--key",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="set this key (TOML value) in a copy of every world; repeatable",
    )
    r.add_argument(
        "--scale",
        action="append",
        default=[],
        metavar="SECTION.KEY=FACTOR",
        help="multiply this number, which every world sets, in a copy of every world (a diagnostic); repeatable",
    )
    c = sub.add_parser("compare", help="pair two measurements world by world")
    c.add_argument("a", help="the base's --out directory")
    c.add_argument("b", help="the change's --out directory")
    args = parser.parse_args()
    if args.command == "run":
        run(args)
    else:
        compare(args)


if __name__ == "__main__":
    main()
