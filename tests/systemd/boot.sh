#!/usr/bin/env bash
# Boots systemd as PID 1 of its own PID and mount namespaces, on a copy-on-write overlay of
# this machine's root: a fresh "machine of this kind" with systemd running, where
# scripts/install.sh can install for real and `systemctl start infotrack` start the unit,
# while every file written lands in DIR/upper and the real root stays untouched.
# Usage (as root): unshare --pid --fork --mount --mount-proc --propagation private \
#                    bash tests/systemd/boot.sh DIR PROJECT
#   DIR      an empty folder on the root filesystem (upper, work, merged are made in it)
#   PROJECT  the project folder, bound at the same path inside (it may be on another mount)
# Used by tests/install_systemd.rs, which enters the namespaces with nsenter.
set -euo pipefail
dir="$1"
project="$2"
mkdir -p "$dir/upper" "$dir/work" "$dir/merged"
mount -t overlay overlay -o "lowerdir=/,upperdir=$dir/upper,workdir=$dir/work" "$dir/merged"
mount --rbind /dev "$dir/merged/dev"
mount -t tmpfs tmpfs "$dir/merged/run"
mkdir -p "$dir/merged$project"
mount --bind "$project" "$dir/merged$project"
# basic.target: no getty or the machine's other services, only what a unit needs.
exec chroot "$dir/merged" /lib/systemd/systemd --system --unit=basic.target --log-target=console
