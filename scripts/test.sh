#!/usr/bin/env bash
# The whole test suite: installs what it needs, then formatting, lints, unit, property and
# integration tests. .ci/run calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo fmt --all -- --check
cargo clippy --release --all-targets -- -D warnings
cargo test --release --all-targets
# The real autopilots (SITL), when their builds are beside the project.
bash scripts/sitl-test.sh
