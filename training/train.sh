#!/usr/bin/env bash
# Reproduces the shipped model: records the training data from the simulated paper
# scenario with infotrack, trains the DMMN, exports models/dmmn.onnx, models/dmmn.json and
# the parity fixture models/dmmn_parity.json.
#
#   python3 -m venv .venv-train && .venv-train/bin/pip install -r training/requirements.txt
#   bash training/train.sh .venv-train/bin/python
#
# PyTorch is a ~3 GB download: it is not part of the README's two commands or of CI,
# which use the shipped model.
set -euo pipefail
cd "$(dirname "$0")/.."
py=${1:-python3}
duration=1800
seed=1
data=data/lab-${duration}s-seed${seed}.csv
cargo build --release --quiet
./target/release/infotrack dataset --duration "$duration" --seed "$seed" --out "$data"
"$py" training/train_dmmn.py --data "$data" --out models \
  --recipe "infotrack dataset --duration $duration --seed $seed (config/default.toml)"
