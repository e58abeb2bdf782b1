#!/usr/bin/env bash
# The main job on the embedded default (the paper's lab scenario): installs what it needs,
# builds, and runs the daemon closed loop for the paper's 90 s: the simulated target on its
# roads, the synthetic camera, the AprilTag detector, the particle filter with the shipped
# DMMN and EER guidance, flying the in-process mock PX4 through real MAVLink. Ends with the
# metrics table; logs, the MAVLink .tlog and plots go to out/. Extra arguments go to
# `infotrack run` (e.g. --vehicle mock:ardupilot --seed 3).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --quiet
exec ./target/release/infotrack run --out out "$@"
