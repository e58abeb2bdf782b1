#!/usr/bin/env python3
"""Where the filter steps without a measurement of the tag go, per guidance and motion model.

Reads the per-run step files an `infotrack sim --out D` run writes (D/<guidance>_<motion>/
runNNN.csv) and sorts every filter step of every run into one cause, the first that holds:

  measured       the tag was measured (their share is the sim table's %FOV)
  before_first   the target not yet seen in this run (the search from the cue)
  occluded       the target under an occlusion (no guidance law sees it there)
  in_view        the target in the footprint, not occluded, and still not measured
  est_lt30       the estimate within 30 m of the target: the drone elsewhere (its dynamics,
                 the plan's choice)
  est_30_100     the estimate 30-100 m off
  est_gt100      the estimate more than 100 m off: the target lost

and prints one row of percentages (of all steps) per directory. BENCHMARKS.md reads the field worlds with it.

Usage: python3 scripts/frame-causes.py D [D ...]
"""
import csv
import pathlib
import sys

CAUSES = ["measured", "before_first", "occluded", "in_view", "est_lt30", "est_30_100", "est_gt100"]


def cause(row, seen):
    """The cause of one step (a dict from the CSV); `seen`: a measurement came before."""
    if row["measured"] == "1":
        return "measured"
    if not seen:
        return "before_first"
    if row["target_occluded"] == "1":
        return "occluded"
    if row["target_in_footprint"] == "1":
        return "in_view"
    error_m = float(row["estimation_error_m"])
    if error_m < 30.0:
        return "est_lt30"
    return "est_30_100" if error_m < 100.0 else "est_gt100"


def count(run_dir):
    """Steps per cause over every runNNN.csv in `run_dir`."""
    counts = dict.fromkeys(CAUSES, 0)
    files = sorted(run_dir.glob("run*.csv"))
    if not files:
        sys.exit(f"frame-causes: no run*.csv in {run_dir} (an `infotrack sim --out D` directory?)")
    for path in files:
        seen = False
        with path.open(newline="") as f:
            for line, row in enumerate(csv.DictReader(f), start=2):
                try:
                    c = cause(row, seen)
                except (KeyError, ValueError) as e:
                    sys.exit(f"frame-causes: {path}, line {line}: {e!r}")
                seen = seen or c == "measured"
                counts[c] += 1
    return counts


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print("directory | " + " | ".join(CAUSES))
    for arg in sys.argv[1:]:
        root = pathlib.Path(arg)
        dirs = [d for d in sorted(root.iterdir()) if d.is_dir()] if root.is_dir() else []
        for d in dirs or [root]:
            counts = count(d)
            total = sum(counts.values())
            cells = " | ".join(f"{100.0 * counts[c] / total:.1f}" for c in CAUSES)
            print(f"{d} | {cells}")


if __name__ == "__main__":
    main()
