#!/usr/bin/env bash
# An arm64 Debian root for cross-building and running infotrack with OpenCV: Debian's arm64
# OpenCV (and the fontconfig and freetype the plots link) with every library they need,
# extracted by mmdebstrap from this machine's own apt sources (so its versions are this
# machine's arm64 packages'), never installed here. Debian's arm64 OpenCV development
# packages cannot be installed beside the amd64 ones (libgdal is not Multi-Arch: same), so
# the cross build links against this folder instead.
#
#   bash scripts/arm64-sysroot.sh DIR
#
# Writes DIR/root (the arm64 root, with the .deb files it came from kept in
# var/cache/apt/archives), DIR/gcc (the cross linker, told where the root's libraries are,
# so that the libraries OpenCV needs resolve at link time) and DIR/library-path (those
# folders, for running the programs under qemu-user). Does nothing when DIR/root holds the
# same packages already. Exit status 3: mmdebstrap or the packages cannot be had here.
set -euo pipefail
cd "$(dirname "$0")/.."
dir="$1"
packages="libopencv-dev,libfontconfig-dev,libfreetype-dev"
cannot() { echo "arm64-sysroot: cannot $*" >&2; exit 3; }
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"

if [ "$(cat "$dir/root/.infotrack-packages" 2>/dev/null)" != "$packages" ]; then
  command -v mmdebstrap >/dev/null || {
    echo "arm64-sysroot: installing Debian's mmdebstrap" >&2
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      mmdebstrap >/dev/null || cannot "install Debian's mmdebstrap"
  }
  rm -rf "$dir/root"
  mkdir -p "$dir"
  sources=$(cat /etc/apt/sources.list.d/*.sources /etc/apt/sources.list 2>/dev/null || true)
  echo "arm64-sysroot: extracting arm64 $packages and what they need into $dir/root" >&2
  # The variant `extract` unpacks the packages and their dependencies, and runs nothing.
  printf '%s\n' "$sources" | mmdebstrap --quiet --variant=extract --architectures=arm64 \
    --include="$packages" --skip=cleanup/apt/cache bookworm "$dir/root" - ||
    cannot "extract Debian's arm64 $packages (mmdebstrap)"
  printf '%s' "$packages" >"$dir/root/.infotrack-packages"
fi

# Every folder of the root that holds a shared library: OpenCV's dependencies live in a few
# (BLAS and LAPACK in their own, which Debian's alternatives would link in place).
find "$dir/root" \( -name 'lib*.so.*' -o -name 'lib*.so' \) -printf '%h\n' | sort -u \
  >"$dir/library-dirs"
paste -sd: "$dir/library-dirs" >"$dir/library-path"
{
  echo '#!/bin/sh'
  echo '# The arm64 cross linker, with the arm64 root'"'"'s library folders to resolve from.'
  printf 'exec aarch64-linux-gnu-gcc "$@"'
  sed 's/^/ -Wl,-rpath-link,/' "$dir/library-dirs" | tr -d '\n'
  echo
} >"$dir/gcc"
chmod +x "$dir/gcc"
