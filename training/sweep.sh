#!/usr/bin/env bash
# The comparison behind the shipped model's choices (input normalisation, output
# convention, width): one-step validation RMSE of each variant on the same data.
# Usage: bash training/sweep.sh DATA.csv [PYTHON]
set -euo pipefail
data=$1
py=${2:-python3}
here=$(dirname "$0")
run() {
  echo "== $*"
  "$py" "$here/train_dmmn.py" --data "$data" --no-export --epochs 300 "$@" 2>&1 | tail -1
}
run --input-norm none --output absolute
run --input-norm workspace --output absolute
run --input-norm workspace --output displacement
run --input-norm last --output displacement
run --input-norm workspace --output displacement --width 16 --head-size 4 --ff 64
run --input-norm workspace --output displacement --dropout 0.0
