#!/usr/bin/env bash
# The SITL suite: flies infotrack against the real PX4 (SIH) and ArduCopter SITL builds in
# ../shared/sitl (tests/sitl.rs). Prepares a runnable copy of the builds in a temporary
# folder (PX4's command links are stored as text files there), then runs the suite. Says
# plainly, and succeeds, when the builds are not there. INFOTRACK_SITL_TESTS=NAME runs only the
# tests whose names contain NAME; INFOTRACK_SITL_KEEP=DIR keeps each flight's outputs
# (steps.csv, flight.csv, link.tlog, infotrack's log) in DIR for a look afterwards.
set -euo pipefail
cd "$(dirname "$0")/.."
src="${INFOTRACK_SITL_SOURCE:-../shared/sitl}"
if [ ! -x "$src/px4/bin/px4" ] || [ ! -x "$src/arducopter/bin/arducopter" ]; then
  echo "SITL suite NOT RUN: no SITL builds at $src (expected px4/bin/px4 and arducopter/bin/arducopter)"
  exit 0
fi
copy="$(mktemp -d)"
trap 'rm -rf "$copy"' EXIT
bash scripts/sitl-copy.sh "$src" "$copy"
echo "SITL suite: PX4 SIH and ArduCopter from $src (copy in $copy)"
# The SITL builds fly on the wall clock and degrade when the machine is busy (PX4 SIH's
# lab flight sees the target less often): say how busy it is before they start.
echo "SITL suite: load average $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores; busiest processes:"
ps -eo pcpu,etimes,comm --sort=-pcpu | head -6 || true
INFOTRACK_SITL="$copy" cargo test --release --test sitl -- "${INFOTRACK_SITL_TESTS:-}" --ignored --test-threads=1 --nocapture
