#!/usr/bin/env bash
# A Monte Carlo campaign on Slurm: an array job of N shards (`infotrack sim ... --shard K/N
# --json DIR/shard-K.json`), then a job that waits for all of them and joins them
# (`infotrack merge`) into DIR/results.json, DIR/metrics.png and DIR/report.md, the
# table in DIR/merge.log. The merged result is the campaign run in one process.
#
#   scripts/slurm-campaign.sh --shards 16 --dir campaigns/town -- \
#       --config config/town.toml --runs 200 --guidance eer,pfwm,lawn,truth --seed 7
#
# Options before `--`: --shards N (required), --dir DIR (required), --infotrack PATH (the
# program every node runs; default: `infotrack` on the PATH), --wait (return when the merge
# has run, with its exit status), and anything else for sbatch (e.g. --partition=P,
# --time=1:00:00, --cpus-per-task=2). After `--`: the `infotrack sim` arguments.
set -euo pipefail

shards="" dir="" bin=infotrack wait=() sbatch_args=()
while [ $# -gt 0 ]; do
    case $1 in
        --shards) shards=$2; shift 2 ;;
        --dir) dir=$2; shift 2 ;;
        --infotrack) bin=$2; shift 2 ;;
        --wait) wait=(--wait); shift ;;
        --) shift; break ;;
        *) sbatch_args+=("$1"); shift ;;
    esac
done
[[ $shards =~ ^[1-9][0-9]*$ ]] || { echo "slurm-campaign.sh: --shards N (N >= 1) is required" >&2; exit 2; }
[ -n "$dir" ] || { echo "slurm-campaign.sh: --dir DIR is required" >&2; exit 2; }
[ $# -gt 0 ] || { echo "slurm-campaign.sh: give the infotrack sim arguments after --" >&2; exit 2; }
command -v sbatch >/dev/null || { echo "slurm-campaign.sh: sbatch not found: is this a Slurm login node?" >&2; exit 1; }
bin=$(command -v "$bin") || { echo "slurm-campaign.sh: the infotrack program was not found" >&2; exit 1; }
mkdir -p "$dir"
dir=$(realpath "$dir")

# The shard's index comes from Slurm on the node: $SLURM_ARRAY_TASK_ID, quoted for later.
sim=$(printf '%q ' "$bin" sim "$@" --quiet --shard)
array=$(sbatch --parsable "${sbatch_args[@]}" --job-name=infotrack-shards \
    --array="0-$((shards - 1))" --output="$dir/shard-%a.log" \
    --wrap="$sim \"\$SLURM_ARRAY_TASK_ID/$shards\" --json \"$dir/shard-\$SLURM_ARRAY_TASK_ID.json\"")
array=${array%%;*}
echo "shards: job $array (array 0-$((shards - 1))), logs $dir/shard-K.log"
merge=$(printf '%q ' "$bin" merge)
files=$(for k in $(seq 0 $((shards - 1))); do printf '%q ' "$dir/shard-$k.json"; done)
job=$(sbatch --parsable "${wait[@]}" "${sbatch_args[@]}" --job-name=infotrack-merge \
    --dependency="afterok:$array" --kill-on-invalid-dep=yes --output="$dir/merge.log" \
    --wrap="$merge $files --out $(printf '%q' "$dir")")
echo "merge: job ${job%%;*}, table in $dir/merge.log, results in $dir/results.json"
