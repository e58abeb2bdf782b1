#!/usr/bin/env bash
# Installs what infotrack needs to build and run on a fresh Debian machine with Rust:
# - Debian packages: font rendering for plots (fontconfig, freetype, DejaVu fonts),
#   pkg-config, OpenCV 4.6 with contrib (camera capture, calibration files, solvePnP),
#   clang/libclang (the opencv crate generates its bindings with it at build time), and
#   GStreamer's base/good plugins (GStreamer camera pipelines);
# - the ONNX Runtime shared library (for the learned motion model), taken from PyPI's
#   onnxruntime==1.31.1 wheel into .deps/onnxruntime/.
# Idempotent: does nothing when everything is present.
set -euo pipefail
cd "$(dirname "$0")/.."

need=()
for pkg in pkg-config libfontconfig1-dev libfreetype-dev fonts-dejavu-core \
  libopencv-dev libopencv-contrib-dev clang libclang-dev \
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good; do
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

ORT_VERSION=1.31.1
ORT_DIR=.deps/onnxruntime
if [ ! -f "$ORT_DIR/libonnxruntime.so.$ORT_VERSION" ]; then
  echo "setup: fetching ONNX Runtime $ORT_VERSION (PyPI wheel onnxruntime==$ORT_VERSION) into $ORT_DIR" >&2
  command -v python3 >/dev/null 2>&1 || { echo "setup: python3 with pip is needed to fetch ONNX Runtime" >&2; exit 1; }
  tmp=$(mktemp -d)
  python3 -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    -d "$tmp" "onnxruntime==$ORT_VERSION"
  mkdir -p "$ORT_DIR"
  python3 - "$tmp" "$ORT_DIR" <<'PY'
import glob, os, sys, zipfile
src, dst = sys.argv[1], sys.argv[2]
wheels = glob.glob(os.path.join(src, "onnxruntime-*.whl"))
if not wheels:
    sys.exit("setup: no onnxruntime wheel was downloaded")
with zipfile.ZipFile(wheels[0]) as z:
    libs = [n for n in z.namelist() if n.startswith("onnxruntime/capi/libonnxruntime")]
    if not libs:
        sys.exit(f"setup: {wheels[0]} has no libonnxruntime")
    for n in libs:
        with z.open(n) as f, open(os.path.join(dst, os.path.basename(n)), "wb") as out:
            out.write(f.read())
PY
  rm -rf "$tmp"
fi

# The stock MAVLink clients (MAVSDK, pymavlink, MAVProxy from PyPI) the tests fly the mock
# with: a virtual environment in .deps/stock-clients, pinned in tests/stock_clients/requirements.txt.
SC_DIR=.deps/stock-clients
SC_REQ=tests/stock_clients/requirements.txt
if ! cmp -s "$SC_REQ" "$SC_DIR/installed-requirements.txt" 2>/dev/null; then
  echo "setup: installing the stock MAVLink clients ($SC_REQ) into $SC_DIR" >&2
  rm -rf "$SC_DIR"
  python3 -m venv "$SC_DIR"
  "$SC_DIR/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
    --only-binary=:all: -r "$SC_REQ"
  cp "$SC_REQ" "$SC_DIR/installed-requirements.txt"
fi

# SciPy, which the paired statistics are checked against (tests/paired_stats_scipy.rs): a
# virtual environment in .deps/stats, pinned in tests/stats/requirements.txt.
ST_DIR=.deps/stats
ST_REQ=tests/stats/requirements.txt
if ! cmp -s "$ST_REQ" "$ST_DIR/installed-requirements.txt" 2>/dev/null; then
  echo "setup: installing SciPy ($ST_REQ) into $ST_DIR" >&2
  rm -rf "$ST_DIR"
  python3 -m venv "$ST_DIR"
  "$ST_DIR/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
    --only-binary=:all: -r "$ST_REQ"
  cp "$ST_REQ" "$ST_DIR/installed-requirements.txt"
fi
