#!/usr/bin/env bash
# Installs what infotrack needs to build and run on a fresh Debian machine with Rust:
# Debian packages for font rendering in plots (fontconfig, freetype, DejaVu fonts) and
# pkg-config. Idempotent: does nothing when everything is present.
set -euo pipefail

need=()
for pkg in pkg-config libfontconfig1-dev libfreetype-dev fonts-dejavu-core; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need+=("$pkg")
done
if [ "${#need[@]}" -gt 0 ]; then
  echo "setup: installing Debian packages: ${need[*]}" >&2
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi

for tool in cargo rustfmt cargo-clippy; do
  command -v "$tool" >/dev/null 2>&1 || { echo "setup: $tool not found; install Rust with rustup (components rustfmt, clippy)" >&2; exit 1; }
done
