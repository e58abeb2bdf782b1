#!/usr/bin/env bash
# Boots systemd as PID 1 of its own PID and mount namespaces, on a copy-on-write overlay of
# this machine's root: a fresh "machine of this kind" with systemd running, where
# scripts/install.sh can install for real and `systemctl start infotrack` start the unit,
# while every file written lands in DIR/upper and the real root stays untouched.
# Usage (as root): unshare --pid --fork --mount --mount-proc --propagation private \
#                    bash tests/systemd/boot.sh DIR PROJECT [LOWER]
#   DIR      an empty folder on the root filesystem (upper, work, merged are made in it)
#   PROJECT  the project folder, bound at the same path inside (it may be on another mount)
#   LOWER    the root to boot (default /): another Debian root, such as an arm64 one whose
#            programs the kernel runs through qemu-user-static's binfmt_misc handler
# Used by tests/install_systemd.rs, which enters the namespaces with nsenter.
set -euo pipefail
dir="$1"
project="$2"
lower="${3:-/}"
mkdir -p "$dir/upper" "$dir/work" "$dir/merged"
mount -t overlay overlay -o "lowerdir=$lower,upperdir=$dir/upper,workdir=$dir/work" "$dir/merged"
mount --rbind /dev "$dir/merged/dev"
mount -t tmpfs tmpfs "$dir/merged/run"
mkdir -p "$dir/merged$project"
mount --bind "$project" "$dir/merged$project"
# basic.target: no getty or the machine's other services, only what a unit needs.
exec chroot "$dir/merged" /lib/systemd/systemd --system --unit=basic.target --log-target=console
