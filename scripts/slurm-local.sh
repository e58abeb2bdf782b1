#!/usr/bin/env bash
# A single-node Slurm cluster on this machine for tests and trials: munged, slurmctld and
# slurmd run as root with their configuration, keys, state and logs under DIR, on ports of
# their own, so that nothing of the machine's own is touched.
#
#   scripts/slurm-local.sh start DIR   # start it; waits until the node takes jobs
#   scripts/slurm-local.sh stop DIR    # stop it
#
# Then point Slurm's commands at it: export SLURM_CONF=DIR/slurm.conf. Needs root and
# Debian's slurm-wlm and munge (scripts/setup-tests.sh installs them).
set -euo pipefail

cmd=${1:?usage: slurm-local.sh start|stop DIR}
dir=$(realpath -m "${2:?usage: slurm-local.sh start|stop DIR}")

stop() {
    for pid in "$dir"/slurmd.pid "$dir"/slurmctld.pid "$dir"/munge/munged.pid; do
        [ -f "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
    done
}

# A free TCP port for one of the daemons.
free_port() {
    python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

start() {
    command -v slurmctld >/dev/null && command -v munged >/dev/null ||
        { echo "slurm-local.sh: slurmctld and munged are missing (apt install slurm-wlm munge)" >&2; exit 1; }
    mkdir -p "$dir"/{state,spool,log,munge}
    chmod 700 "$dir/munge"
    local key=$dir/munge/munge.key
    if [ ! -f "$key" ]; then
        dd if=/dev/urandom bs=1 count=1024 of="$key" status=none
        chmod 400 "$key"
    fi
    # --force: munged refuses root and a socket outside its usual directory otherwise.
    munged --force --key-file="$key" --socket="$dir/munge/socket" \
        --pid-file="$dir/munge/munged.pid" --log-file="$dir/log/munged.log" \
        --seed-file="$dir/munge/seed"
    local node
    node=$(slurmd -C | head -1)
    cat >"$dir/slurm.conf" <<CONF
ClusterName=infotrack
SlurmctldHost=$(hostname -s)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge/socket
CredType=cred/munge
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
SwitchType=switch/none
$node State=UNKNOWN
PartitionName=campaign Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF=$dir/slurm.conf
    slurmctld -f "$SLURM_CONF"
    slurmd -f "$SLURM_CONF"
    for _ in $(seq 60); do
        if sinfo -h -o %t 2>/dev/null | grep -qx 'idle'; then
            echo "slurm-local.sh: one node up; export SLURM_CONF=$SLURM_CONF"
            return 0
        fi
        sleep 1
    done
    echo "slurm-local.sh: the node did not come up in 60 s; logs in $dir/log" >&2
    tail -5 "$dir"/log/*.log >&2 || true
    stop
    exit 1
}

case $cmd in
    start) start ;;
    stop) stop ;;
    *) echo "slurm-local.sh: start or stop, not $cmd" >&2; exit 2 ;;
esac
