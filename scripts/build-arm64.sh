#!/usr/bin/env bash
# The arm64 build of infotrack for a companion computer (Raspberry Pi 4/5, Jetson, Radxa:
# aarch64-unknown-linux-gnu), cross-compiled on this x86-64 Debian machine, and its tests
# run as arm64 binaries under qemu-user emulating a Raspberry Pi 4's core (Cortex-A72).
#
#   bash scripts/build-arm64.sh          # builds target/aarch64-unknown-linux-gnu/release/infotrack
#   bash scripts/build-arm64.sh --test   # and runs, under qemu: the core's tests, the
#                                        # detector's, the DMMN's parity with PyTorch on arm64
#                                        # ONNX Runtime, and a 30 s closed loop on the mock
#   bash scripts/build-arm64.sh --deb    # and packs infotrack_VERSION_arm64.deb; with --test
#                                        # also flies its program, and installs, flies,
#                                        # upgrades and removes it under systemd
#   --profile NAME                       # a Cargo profile other than release (the test
#                                        # command's arm64-check builds in a third the time)
#
# Exit status 3: what it needs could not be installed here (no arm64 packages, no Rust
# target, no mount namespaces); it says what, and the test command reports the arm64 suite
# as not run. Any other failure is a failure.
#
# Installs what it needs (as root, or with sudo): Debian's crossbuild-essential-arm64 and
# qemu-user, the arm64 fontconfig and freetype the plots link, the Rust target (rustup),
# and ONNX Runtime for arm64 from the same PyPI package as the amd64 build, into
# .deps/onnxruntime-arm64/.
#
# The arm64 program is built without OpenCV (`--no-default-features`): Debian's arm64
# OpenCV development packages cannot be installed beside the amd64 ones on one machine.
# It flies the simulator and the mock through the synthetic camera and the same AprilTag
# detector, and refuses a real camera, `detect` and `calibrate`, saying why. A real camera
# on the board needs a build with OpenCV, on the board itself (`cargo build --release`).
set -euo pipefail
cd "$(dirname "$0")/.."

test=false deb=false profile=release
while [ $# -gt 0 ]; do
  case "$1" in
    --test) test=true; shift ;;
    --deb) deb=true; shift ;;
    --profile) profile="$2"; shift 2 ;;
    *) echo "build-arm64: unknown option $1 (--test, --deb, --profile NAME)" >&2; exit 2 ;;
  esac
done
cannot() { echo "build-arm64: cannot $*" >&2; exit 3; }

target=aarch64-unknown-linux-gnu
ort_version=1.31.1
ort_dir="$PWD/.deps/onnxruntime-arm64"
ort_lib="$ort_dir/libonnxruntime.so.$ort_version"
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"

# Debian's cross toolchain, qemu and the arm64 libraries the program links.
# The arm64 C library and C++ runtime come from the multiarch packages (what the board has),
# so that its dynamic loader and libc are one release (the cross toolchain's own copy may be
# an older one, and glibc's loader and libc of different releases corrupt each other).
needed=(crossbuild-essential-arm64 qemu-user libc6:arm64 libstdc++6:arm64
  libfontconfig-dev:arm64 libfreetype-dev:arm64)
missing=()
for pkg in "${needed[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "build-arm64: installing Debian's ${missing[*]}" >&2
  dpkg --print-foreign-architectures | grep -qx arm64 || $SUDO dpkg --add-architecture arm64 ||
    cannot "add the arm64 architecture to dpkg"
  $SUDO apt-get update -qq || cannot "update Debian's package lists"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >/dev/null || cannot "install Debian's ${missing[*]}"
fi
rustup target list --installed | grep -qx "$target" || rustup target add "$target" ||
  cannot "add the Rust target $target (rustup)"

# ONNX Runtime for arm64: the library of PyPI's onnxruntime wheel for manylinux aarch64.
if [ ! -f "$ort_lib" ]; then
  echo "build-arm64: fetching ONNX Runtime $ort_version for arm64 (PyPI) into $ort_dir" >&2
  tmp=$(mktemp -d)
  python3 -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    --platform manylinux_2_28_aarch64 --python-version 3.11 -d "$tmp" \
    "onnxruntime==$ort_version" || cannot "download onnxruntime==$ort_version for arm64 (PyPI)"
  mkdir -p "$ort_dir"
  python3 - "$tmp" "$ort_dir" <<'PY'
import glob, os, sys, zipfile
src, dst = sys.argv[1], sys.argv[2]
wheel = glob.glob(os.path.join(src, "onnxruntime-*.whl"))[0]
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        if name.startswith("onnxruntime/capi/libonnxruntime"):
            with open(os.path.join(dst, os.path.basename(name)), "wb") as f:
                f.write(z.read(name))
PY
  rm -rf "$tmp"
fi

# The cross compilers and the arm64 pkg-config files.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export CXX_aarch64_unknown_linux_gnu=aarch64-linux-gnu-g++
export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
export PKG_CONFIG_ALLOW_CROSS=1 PKG_CONFIG_SYSROOT_DIR=/
export PKG_CONFIG_LIBDIR=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig

cargo build --profile "$profile" --locked --target "$target" --no-default-features --bin infotrack
binary="target/$target/$profile/infotrack"
echo "build-arm64: $binary" >&2

# Runs an arm64 program under qemu as a Raspberry Pi 4 core, with the arm64 libraries
# installed beside this machine's own (/lib/aarch64-linux-gnu). ONNX Runtime reads the CPU's
# description from /proc/cpuinfo, which qemu-user leaves the host's (x86-64), and crashes on
# it; the program runs in a private mount namespace that sees a Cortex-A72's instead.
as_pi4() {
  local cpuinfo
  cpuinfo=$(mktemp)
  for n in 0 1 2 3; do
    printf 'processor\t: %s\nBogoMIPS\t: 108.00\nFeatures\t: fp asimd evtstrm crc32 cpuid\n' "$n"
    printf 'CPU implementer\t: 0x41\nCPU architecture: 8\nCPU variant\t: 0x0\n'
    printf 'CPU part\t: 0xd08\nCPU revision\t: 3\n\n'
  done >"$cpuinfo"
  QEMU_CPU=cortex-a72 ORT_DYLIB_PATH="$ort_lib" \
    unshare --mount sh -c 'mount --bind "$0" /proc/cpuinfo && exec qemu-aarch64 "$@"' \
    "$cpuinfo" "$@"
  local status=$?
  rm -f "$cpuinfo"
  return "$status"
}

if $test; then
  # The core's tests, the detector's (the vision crate without OpenCV) and the DMMN's
  # parity, built as arm64 test programs; cargo runs each through as_pi4.
  export -f as_pi4
  export ort_lib
  runner=$(mktemp)
  printf '#!/usr/bin/env bash\nas_pi4 "$@"\n' >"$runner"
  chmod +x "$runner"
  unshare --mount true 2>/dev/null || cannot "make a mount namespace (unshare --mount, as root)"
  CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$runner" cargo test --profile "$profile" \
    --locked --target "$target" -p infotrack-core -p infotrack-vision --no-default-features
  CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$runner" cargo test --profile "$profile" \
    --locked --target "$target" -p infotrack-dmmn --test parity
  rm -f "$runner"
  # A 30 s closed loop on the mock: the daemon, its MAVLink link and the mock on loopback,
  # the synthetic camera through the detector, the DMMN, EER; the lab on a simulated clock.
  flight=$(mktemp -d)
  as_pi4 "$binary" sim --closed-loop --seed 1 --duration 30 --out "$flight/out"
  python3 - "$flight/out/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
frames = s["flight"]["frames_with_tag"]
assert frames > 0, f"the arm64 closed loop never saw the tag: {s['flight']}"
print(f"build-arm64: the arm64 closed loop saw the tag in {frames} frames")
PY
  rm -rf "$flight"
fi

if $deb; then
  package=$(bash scripts/build-deb.sh --arch arm64 --binary "$binary" --onnxruntime "$ort_lib")
  echo "build-arm64: $package" >&2
  if $test; then
    # What the package installs flies: its program, with the ONNX Runtime and the models
    # and configs it carries, unpacked into a folder (dpkg -x) and run under qemu.
    root=$(mktemp -d)
    dpkg -x "$package" "$root"
    (cd "$root/etc/infotrack" && ort_lib="$root/usr/lib/infotrack/libonnxruntime.so.$ort_version" \
      as_pi4 "$root/usr/lib/infotrack/infotrack" sim --closed-loop --config config/outdoor.toml \
      --seed 1 --duration 20 --quiet)
    rm -rf "$root"
    echo "build-arm64: the package's program flew the outdoor world's closed loop" >&2
    # Installed for real: dpkg -i beside this machine's arm64 libraries in a booted systemd,
    # the unit flying the mock, an upgrade, dpkg -r and -P (tests/install_systemd.rs; the
    # kernel runs the arm64 program through qemu-user's binfmt_misc handler).
    version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
    next=$(bash scripts/build-deb.sh --fast --arch arm64 --binary "$binary" \
      --onnxruntime "$ort_lib" --version "$version+1" --out target/debian-test-arm64)
    (unset PKG_CONFIG_ALLOW_CROSS PKG_CONFIG_SYSROOT_DIR PKG_CONFIG_LIBDIR
      INFOTRACK_ARM64_DEB="$PWD/$package" INFOTRACK_ARM64_DEB_NEXT="$PWD/$next" \
        cargo test --release --locked --workspace --test install_systemd -- --ignored \
        --exact the_arm64_package_installs_flies_upgrades_and_removes_cleanly_under_emulation)
    echo "build-arm64: the package installed, flew the mock under systemd, upgraded and was removed" >&2
  fi
fi
