#!/usr/bin/env bash
# Runs a command inside a cgroup limited to a share of one CPU core: how infotrack fares on
# a companion computer's slower core (a quarter of one of this machine's cores is about a
# Raspberry Pi 4's Cortex-A72 core; see BENCHMARKS.md).
#
#   scripts/cpu-budget.sh 0.25 -- infotrack run --config config/outdoor.toml --out flight
#
# cgroup v2 (cpu.max) where the cpu controller is there, else cgroup v1 (cpu.cfs_quota_us);
# needs root. The cgroup is removed when the command ends; the command's exit status is
# the script's.
set -euo pipefail

share=${1:?usage: cpu-budget.sh SHARE -- COMMAND...}
shift
[ "${1:-}" = "--" ] && shift
[ $# -gt 0 ] || { echo "cpu-budget.sh: no command given" >&2; exit 2; }
period=100000
quota=$(python3 -c "import sys; q=round(float(sys.argv[1])*$period); assert 1000<=q<=64*$period; print(q)" "$share") ||
    { echo "cpu-budget.sh: SHARE must be a number of cores from 0.01 to 64, not $share" >&2; exit 2; }
name=infotrack-budget-$$

if grep -qw cpu /sys/fs/cgroup/cgroup.controllers 2>/dev/null; then
    cg=/sys/fs/cgroup/$name
    mkdir "$cg"
    echo "$quota $period" >"$cg/cpu.max"
elif [ -d /sys/fs/cgroup/cpu ]; then
    cg=/sys/fs/cgroup/cpu/$name
    mkdir "$cg"
    echo "$period" >"$cg/cpu.cfs_period_us"
    echo "$quota" >"$cg/cpu.cfs_quota_us"
else
    echo "cpu-budget.sh: no cgroup cpu controller here (/sys/fs/cgroup)" >&2
    exit 1
fi
cleanup() { rmdir "$cg" 2>/dev/null || true; }
trap cleanup EXIT
echo "cpu-budget.sh: $share of one core ($quota us per $period us) in $cg" >&2
# The command runs in a child that joins the cgroup first, so that the script itself
# stays outside and can remove the cgroup afterwards.
status=0
bash -c 'echo $$ > "$1/cgroup.procs"; shift; exec "$@"' _ "$cg" "$@" || status=$?
exit $status
