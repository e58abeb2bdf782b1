#!/usr/bin/env bash
# Installs what the tests and benchmarks need beyond scripts/setup.sh (which the main job
# needs too): pinned Python environments under .deps/ and Debian's osmium-tool.
# - .deps/stock-clients: the stock MAVLink clients (MAVSDK, pymavlink, MAVProxy) the tests
#   fly the mock with;
# - .deps/stats: SciPy, which the paired statistics are checked against;
# - .deps/sumo: Eclipse SUMO and sumolib, the reference traffic (scripts/sumo-traffic.py);
# - osmium-tool: cuts an OpenStreetMap .pbf extract to XML for SUMO's netconvert;
# - slurm-wlm and munge: a one-node Slurm cluster (scripts/slurm-local.sh) that runs a
#   campaign's shards as an array job (scripts/slurm-campaign.sh);
# - .deps/mdbook: mdBook from crates.io, pinned, which builds the book in docs/
#   (tests/docs_book.rs, which also checks every link and anchor of the book itself).
# Idempotent: does nothing when everything is present.
set -euo pipefail
cd "$(dirname "$0")/.."

# Whether Debian's package is installed; with another architecture's copy beside it (the
# arm64 build's multiarch libraries) dpkg needs this machine's architecture named.
installed() {
  dpkg -s "$1" >/dev/null 2>&1 || dpkg -s "$1:$(dpkg --print-architecture)" >/dev/null 2>&1
}

# A virtual environment DIR with the pinned packages of REQ, made again when REQ changes.
venv_from() { # venv_from DIR REQ WHAT
  if ! cmp -s "$2" "$1/installed-requirements.txt" 2>/dev/null; then
    echo "setup: installing $3 ($2) into $1" >&2
    rm -rf "$1"
    python3 -m venv "$1"
    "$1/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
      --only-binary=:all: -r "$2"
    cp "$2" "$1/installed-requirements.txt"
  fi
}

venv_from .deps/stock-clients tests/stock_clients/requirements.txt "the stock MAVLink clients"
venv_from .deps/stats tests/stats/requirements.txt "SciPy"

venv_from .deps/sumo tests/sumo/requirements.txt "Eclipse SUMO"

# A crate's program of one version under .deps/mdbook, built from crates.io.
crate_tool() { # crate_tool CRATE VERSION
  if ! "$PWD/.deps/mdbook/bin/$1" --version 2>/dev/null | grep -q "$2"; then
    echo "setup-tests: building $1 $2 from crates.io into .deps/mdbook" >&2
    cargo install --quiet --locked --root .deps/mdbook "$1" --version "=$2"
  fi
}
crate_tool mdbook 0.5.4

missing=()
for pkg in osmium-tool slurm-wlm munge; do
  installed "$pkg" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup-tests: installing Debian's ${missing[*]}" >&2
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi
