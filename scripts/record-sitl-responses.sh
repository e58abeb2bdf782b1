#!/usr/bin/env bash
# Records the response probe (tests/common/probe.rs) from both SITL builds into
# tests/fixtures/sitl/ as NAME-K.csv (K = 1, 2, ...: px4-sih-K.csv, arducopter-K.csv): the
# real autopilots' answers that tests/mock_calibration.rs holds the mock to, and that the
# SITL suite holds the firmware builds to. One flight of a real autopilot wanders, so
# several are recorded (FLIGHTS, default 3). Run it when the SITL builds change; it
# replaces the old recordings.
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(pwd)/tests/fixtures/sitl"
mkdir -p "$out"
rm -f "$out"/px4-sih-*.csv "$out"/arducopter-*.csv
for _ in $(seq "${FLIGHTS:-3}"); do
  INFOTRACK_RECORD_FIXTURES="$out" INFOTRACK_SITL_TESTS="answers_the_probe" bash scripts/sitl-test.sh
done
ls -l "$out"
