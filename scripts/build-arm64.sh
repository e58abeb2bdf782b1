#!/usr/bin/env bash
# The arm64 build of infotrack for a companion computer (Raspberry Pi 4/5, Jetson, Radxa:
# aarch64-unknown-linux-gnu), cross-compiled on this x86-64 Debian machine, and its tests
# run as arm64 binaries under qemu-user emulating a Raspberry Pi 4's core (Cortex-A72).
#
#   bash scripts/build-arm64.sh          # builds target/aarch64-unknown-linux-gnu/dist/infotrack
#                                        # (Cargo's dist profile: link-time optimised)
#   bash scripts/build-arm64.sh --test   # and runs, under qemu: the core's tests, the
#                                        # detector's, the DMMN's parity with PyTorch on arm64
#                                        # ONNX Runtime, and a 30 s closed loop on the mock
#   bash scripts/build-arm64.sh --deb    # and packs infotrack_VERSION_arm64.deb; with --test
#                                        # also boots an arm64 Debian 12 with systemd under
#                                        # qemu, where apt installs the package, its unit
#                                        # flies the mock, and it is upgraded, removed and
#                                        # purged (--no-opencv: dpkg installs it beside this
#                                        # machine's arm64 libraries instead)
#   --profile NAME                       # a Cargo profile other than dist (the test
#                                        # command's arm64-check builds in a third the time)
#   --board                              # with --deb: that booted arm64 Debian 12, without
#                                        # the other tests
#   --no-opencv                          # without OpenCV: no arm64 root to extract, and a
#                                        # program that refuses a real camera
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
# The arm64 program links Debian's arm64 OpenCV from an arm64 root extracted beside the
# project (scripts/arm64-sysroot.sh, .deps/arm64-sysroot): Debian's arm64 OpenCV development
# packages cannot be installed beside the amd64 ones on one machine. Its package depends on
# the board's own OpenCV packages. Under qemu the programs run on that root's loader and
# libraries. With --no-opencv it is built without (`--no-default-features`) and refuses a
# real camera, `detect` and `calibrate`, saying why.
set -euo pipefail
cd "$(dirname "$0")/.."

test=false deb=false profile=dist opencv=true board_check=false
while [ $# -gt 0 ]; do
  case "$1" in
    --test) test=true; shift ;;
    --deb) deb=true; shift ;;
    --profile) profile="$2"; shift 2 ;;
    --no-opencv) opencv=false; shift ;;
    --board) board_check=true; shift ;;
    *) echo "build-arm64: unknown option $1 (--test, --deb, --board, --profile NAME, --no-opencv)" >&2; exit 2 ;;
  esac
done
if $board_check && ! $deb; then
  echo "build-arm64: --board installs the package: it needs --deb" >&2
  exit 2
fi
# The package with OpenCV is tested as on a board (its dependencies are the board's).
$test && $deb && $opencv && board_check=true
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

# The cross compilers and the arm64 pkg-config files: the arm64 root's with OpenCV, else
# this machine's multiarch ones.
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export CXX_aarch64_unknown_linux_gnu=aarch64-linux-gnu-g++
export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
export PKG_CONFIG_ALLOW_CROSS=1
sysroot_dir="$PWD/.deps/arm64-sysroot"
sysroot="$sysroot_dir/root"
features=()
if $opencv; then
  status=0
  bash scripts/arm64-sysroot.sh "$sysroot_dir" || status=$?
  [ "$status" -eq 0 ] || exit "$status"
  export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER="$sysroot_dir/gcc"
  export PKG_CONFIG_SYSROOT_DIR="$sysroot"
  export PKG_CONFIG_LIBDIR="$sysroot/usr/lib/aarch64-linux-gnu/pkgconfig:$sysroot/usr/share/pkgconfig"
else
  features=(--no-default-features)
  export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
  export PKG_CONFIG_SYSROOT_DIR=/
  export PKG_CONFIG_LIBDIR=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig
fi

cargo build --profile "$profile" --locked --target "$target" "${features[@]}" --bin infotrack
binary="target/$target/$profile/infotrack"
echo "build-arm64: $binary" >&2

# Runs an arm64 program under qemu as a Raspberry Pi 4 core: with OpenCV on the arm64
# root's loader and libraries (QEMU_LD_PREFIX, which programs it starts inherit), else on
# the arm64 libraries installed beside this machine's own (/lib/aarch64-linux-gnu). ONNX
# Runtime reads the CPU's description from /proc/cpuinfo, which qemu-user leaves the host's
# (x86-64), and crashes on it; the program runs in a private mount namespace that sees a
# Cortex-A72's instead.
export QEMU_CPU=cortex-a72 qemu_library_path=""
if $opencv; then
  export QEMU_LD_PREFIX="$sysroot"
  qemu_library_path=$(cat "$sysroot_dir/library-path")
fi
export qemu_library_path
# /proc/cpuinfo of a Raspberry Pi 4: four Cortex-A72 cores.
a72_cpuinfo() {
  for n in 0 1 2 3; do
    printf 'processor\t: %s\nBogoMIPS\t: 108.00\nFeatures\t: fp asimd evtstrm crc32 cpuid\n' "$n"
    printf 'CPU implementer\t: 0x41\nCPU architecture: 8\nCPU variant\t: 0x0\n'
    printf 'CPU part\t: 0xd08\nCPU revision\t: 3\n\n'
  done
}
as_pi4() {
  local cpuinfo
  cpuinfo=$(mktemp)
  a72_cpuinfo >"$cpuinfo"
  env ${ort_lib:+ORT_DYLIB_PATH="$ort_lib"} \
    unshare --mount sh -c 'mount --bind "$0" /proc/cpuinfo && exec qemu-aarch64 "$@"' \
    "$cpuinfo" ${qemu_library_path:+-E "LD_LIBRARY_PATH=$qemu_library_path"} "$@"
  local status=$?
  rm -f "$cpuinfo"
  return "$status"
}

# qemu-aarch64 as the kernel's handler of arm64 programs (binfmt_misc; flag F: the kernel
# holds the interpreter open); removed again by unregister_arm64_handler if this added it.
handler=/proc/sys/fs/binfmt_misc/qemu-aarch64 registered_handler=false
register_arm64_handler() {
  mountpoint -q /proc/sys/fs/binfmt_misc ||
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc ||
    cannot "mount binfmt_misc (as root) to run arm64 programs a test starts"
  [ -e "$handler" ] && return 0
  local qemu=/usr/bin/qemu-aarch64
  ${static_handler:-false} && qemu=/usr/bin/qemu-aarch64-static
  printf '%s' ':qemu-aarch64:M::\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\xb7\x00:\xff\xff\xff\xff\xff\xff\xff\x00\xff\xff\xff\xff\xff\xff\xff\xff\xfe\xff\xff\xff:'"$qemu"':F' \
    >/proc/sys/fs/binfmt_misc/register || cannot "register qemu-aarch64 with binfmt_misc"
  registered_handler=true
  trap unregister_arm64_handler EXIT
}
unregister_arm64_handler() {
  if $registered_handler && [ -e "$handler" ]; then echo -1 >"$handler"; fi
  registered_handler=false
}

if $test; then
  # The core's tests, the detector's and the camera's (the vision crate, with OpenCV unless
  # --no-opencv) and the DMMN's parity, built as arm64 test programs; cargo runs each
  # through as_pi4.
  export -f as_pi4 a72_cpuinfo
  export ort_lib
  runner=$(mktemp)
  printf '#!/usr/bin/env bash\nas_pi4 "$@"\n' >"$runner"
  chmod +x "$runner"
  unshare --mount true 2>/dev/null || cannot "make a mount namespace (unshare --mount, as root)"
  CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$runner" cargo test --profile "$profile" \
    --locked --target "$target" -p infotrack-core -p infotrack-vision "${features[@]}"
  CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$runner" cargo test --profile "$profile" \
    --locked --target "$target" -p infotrack-dmmn --test parity
  if $opencv; then
    # The program's `detect` and `calibrate` through arm64 OpenCV: the tests render tags and
    # chessboards and run the program on them. It starts as their child, so the kernel
    # must hand arm64 programs to qemu (binfmt_misc), for the while of these tests.
    register_arm64_handler
    CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$runner" cargo test --profile "$profile" \
      --locked --target "$target" -p infotrack --test detect_cli --test calibrate_cli
    unregister_arm64_handler
  fi
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

# The ignored test TEST of tests/install_systemd.rs on the package and on a later version
# of it (the upgrade), with VAR=VALUE settings added. A host build: the cross build's
# pkg-config settings are unset, and QEMU_LD_PREFIX too, with which qemu would look up every
# path of a booted arm64 root in the build's arm64 root first.
install_test() { # install_test TEST [VAR=VALUE ...]
  local name=$1 version next
  shift
  version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
  next=$(bash scripts/build-deb.sh --fast --arch arm64 --binary "$binary" \
    --onnxruntime "$ort_lib" "${from_root[@]}" --version "$version+1" --out target/debian-test-arm64)
  (unset PKG_CONFIG_ALLOW_CROSS PKG_CONFIG_SYSROOT_DIR PKG_CONFIG_LIBDIR QEMU_LD_PREFIX
    env "$@" INFOTRACK_ARM64_DEB="$PWD/$package" INFOTRACK_ARM64_DEB_NEXT="$PWD/$next" \
      cargo test --release --locked --workspace --test install_systemd -- --ignored --exact "$name")
}

if $deb; then
  from_root=()
  $opencv && from_root=(--sysroot "$sysroot")
  package=$(bash scripts/build-deb.sh --arch arm64 --binary "$binary" --onnxruntime "$ort_lib" \
    "${from_root[@]}")
  echo "build-arm64: $package" >&2
  if $test && ! $opencv; then
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
    # kernel runs the arm64 program through qemu-user's binfmt_misc handler). This package
    # needs no arm64 library this machine lacks; the one with OpenCV needs the arm64
    # OpenCV, which cannot be installed beside the amd64 one, so it goes on a booted arm64
    # Debian 12 instead (below).
    install_test the_arm64_package_installs_flies_upgrades_and_removes_cleanly_under_emulation
    echo "build-arm64: the package installed, flew the mock under systemd, upgraded and was removed" >&2
  fi
fi

if $board_check && $deb; then
  # The package as on a board: an arm64 Debian 12 (mmdebstrap's `essential` variant with
  # systemd, apt and the package's dependencies) boots with its own systemd as PID 1, every
  # program of it run by the kernel through qemu-user-static, which needs no library of this
  # machine's inside the root. There apt installs the package, its unit flies the mock as the
  # user its script created, an upgrade keeps an edited conffile, and dpkg removes it
  # (keeping the configs) and purges it (leaving nothing, the user gone):
  # tests/install_systemd.rs. systemd-binfmt is masked in the root: at boot it would flush
  # the kernel's handlers, the one running the root's programs among them.
  # arch-test: mmdebstrap checks with it that this machine runs the root's programs.
  { command -v qemu-aarch64-static && command -v arch-test; } >/dev/null ||
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      qemu-user-static arch-test >/dev/null || cannot "install Debian's qemu-user-static and arch-test"
  if [ -e "$handler" ] && ! grep -q 'qemu-aarch64-static' "$handler"; then
    echo "build-arm64: $handler runs arm64 programs with a qemu that needs this machine's libraries; --board needs qemu-aarch64-static there" >&2
    exit 1
  fi
  static_handler=true register_arm64_handler
  board=$(mktemp -d /var/tmp/infotrack-board.XXXXXX)
  trap 'rm -rf "$board"; unregister_arm64_handler' EXIT
  depends=$(dpkg-deb -f "$package" Depends | sed 's/ *([^)]*)//g; s/ //g')
  printf '%s\n' "$(cat /etc/apt/sources.list.d/*.sources /etc/apt/sources.list 2>/dev/null)" |
    mmdebstrap --quiet --variant=essential --architectures=arm64 \
      --include="systemd,systemd-sysv,dbus,apt,$depends" \
      --customize-hook='ln -sf /dev/null "$1/etc/systemd/system/systemd-binfmt.service"' \
      bookworm "$board/root" -
  install_test the_arm64_package_installs_flies_upgrades_and_removes_cleanly_on_a_booted_arm64_debian \
    INFOTRACK_ARM64_BOARD_ROOT="$board/root"
  echo "build-arm64: on a booted arm64 Debian 12, apt installed the package, its unit flew, it was upgraded, removed and purged cleanly" >&2
fi
