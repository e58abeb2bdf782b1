#!/usr/bin/env bash
# Reproduces the shipped field-scale model models/outdoor/ for config/outdoor.toml (and the
# field configs that share its world): two hours of the simulated car on that road graph,
# positions normalised by the workspace and the next step predicted as a displacement (a
# 10 m/s car moves 3.3 m per step across a 1.6 km workspace: absolute outputs would drown
# the step in the scale). The world signature infotrack dataset writes beside the data is
# copied into models/outdoor/dmmn.json; the model is refused in any other world.
#
#   python3 -m venv .venv-train && .venv-train/bin/pip install -r training/requirements.txt
#   bash training/train_outdoor.sh .venv-train/bin/python
set -euo pipefail
cd "$(dirname "$0")/.."
py=${1:-python3}
duration=7200
seed=1
data=data/outdoor-${duration}s-seed${seed}.csv
cargo build --release --quiet
./target/release/infotrack dataset --config config/outdoor.toml --duration "$duration" --seed "$seed" --out "$data"
"$py" training/train_dmmn.py --data "$data" --out models/outdoor \
  --input-norm workspace --output displacement --cv-max-speed 14 \
  --recipe "infotrack dataset --config config/outdoor.toml --duration $duration --seed $seed; --input-norm workspace --output displacement --cv-max-speed 14"
