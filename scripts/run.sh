#!/usr/bin/env bash
# The main job on the embedded default (the paper's lab scenario): installs what it needs,
# builds, runs the Monte Carlo benchmark of the guidance laws, prints the results table and
# writes logs, plots and JSON to out/. Extra arguments go to `infotrack sim`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --quiet
exec ./target/release/infotrack sim --runs 10 --guidance eer,pfwm,lawn,kf --motion dmmn --out out --json out/results.json "$@"
