#!/usr/bin/env bash
# The whole test suite: installs what it needs, then formatting, lints, unit, property and
# integration tests. .ci/run calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."
# The core first, before the setup installs anything: its tests build and pass without
# OpenCV, ONNX Runtime or any system package (only Rust and crates.io).
cargo test --release -p infotrack-core
bash scripts/setup.sh
bash scripts/setup-tests.sh
cargo fmt --all -- --check
cargo clippy --release --workspace --all-targets -- -D warnings
# Four tests at a time within each test program (libtest's default is one per core): most
# integration tests fly the mock on the wall clock and mostly wait, and two at a time kept
# the suite near eight minutes of a 30-minute CI budget (four: under six).
RUST_TEST_THREADS="${RUST_TEST_THREADS:-4}" cargo test --release --workspace --all-targets
# The arm64 build under qemu-user: the core's and the detector's tests, the DMMN's parity,
# a closed-loop flight, and the arm64 package's program flying from its unpacked files.
arm64=0
bash scripts/build-arm64.sh --profile arm64-check --test --deb || arm64=$?
case $arm64 in
  0) ;;
  3) echo "arm64 suite NOT RUN: what it needs could not be installed here (above)" ;;
  *) exit "$arm64" ;;
esac
# The real autopilots (SITL), when their builds are beside the project.
bash scripts/sitl-test.sh
