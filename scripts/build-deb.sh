#!/usr/bin/env bash
# Builds the Debian package: scripts/install.sh stages the files (the program and ONNX
# Runtime in /usr/lib/infotrack, /usr/bin/infotrack, the configs and models in
# /etc/infotrack as conffiles, the unit in /lib/systemd/system), then dpkg-deb packs them
# with the scripts that create the user `infotrack` and remove it on purge.
#
#   bash scripts/build-deb.sh [--binary FILE] [--version V] [--out DIR] [--fast]
#                             [--arch ARCH --onnxruntime FILE [--sysroot DIR]]
#
# Without --binary it builds the program with Cargo's `dist` profile: link-time optimisation
# over the whole program makes it a third smaller and the lab's Monte Carlo a quarter faster
# than the release build (BENCHMARKS.md, "Size and build").
# --fast packs with gzip instead of xz (tests: seconds instead of half a minute).
# --arch arm64 packs a cross-built program (scripts/build-arm64.sh --deb does) with its
# architecture's ONNX Runtime; its dependencies come from the arm64 libraries installed
# beside this machine's own (dpkg multiarch), or with --sysroot from the packages an arm64
# root was extracted from (scripts/arm64-sysroot.sh keeps them in DIR/var/cache/apt/archives):
# each library the program needs, as its package at least at that package's upstream version.
# Writes DIR/infotrack_V_ARCH.deb (default: target/debian/, the version Cargo's, the
# architecture this machine's) and prints its path. Install with
# `apt install ./infotrack_V_ARCH.deb`, then edit /etc/infotrack/config/px4.toml and
# `systemctl enable --now infotrack`.
set -euo pipefail
cd "$(dirname "$0")/.."

binary="" version="" out="target/debian" compression=(-Zxz) arch="" ort=() sysroot=""
while [ $# -gt 0 ]; do
  case "$1" in
    --binary) binary="$2"; shift 2 ;;
    --version) version="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --fast) compression=(-Zgzip -z1); shift ;;
    --arch) arch="$2"; shift 2 ;;
    --onnxruntime) ort=(--onnxruntime "$2"); shift 2 ;;
    --sysroot) sysroot="$2"; shift 2 ;;
    *) echo "build-deb: unknown option $1 (--binary FILE, --version V, --out DIR, --fast, --arch ARCH, --onnxruntime FILE, --sysroot DIR)" >&2; exit 2 ;;
  esac
done
[ -n "$version" ] || version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
native=$(dpkg --print-architecture)
[ -n "$arch" ] || arch=$native
if [ "$arch" != "$native" ] && { [ -z "$binary" ] || [ ${#ort[@]} -eq 0 ]; }; then
  echo "build-deb: a package for $arch needs its --binary and --onnxruntime" >&2
  exit 2
fi
# The GNU triplet of the package's architecture: its strip and objdump read the program.
triplet=$(dpkg-architecture -a"$arch" -qDEB_HOST_GNU_TYPE 2>/dev/null)
tools=""
[ "$arch" != "$native" ] && tools="$triplet-"
if [ -z "$binary" ]; then
  cargo build --profile dist --locked --bin infotrack
  binary=target/dist/infotrack
fi

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
bash scripts/install.sh --destdir "$stage" --prefix /usr --files-only --binary "$binary" \
  "${ort[@]}" >&2
rmdir "$stage/etc/systemd/system" "$stage/etc/systemd" 2>/dev/null || true
# The package's program is stripped: its line tables stay in the build's own binary.
"${tools}strip" --strip-debug "$stage/usr/lib/infotrack/infotrack"

# What the program links to, as Debian package dependencies (dpkg-shlibdeps reads them
# from the shared libraries' own packages). ONNX Runtime ships inside the package.
if [ -n "$sysroot" ]; then
  depends=$("${tools}objdump" -p "$stage/usr/lib/infotrack/infotrack" | sed -n 's/^ *NEEDED *//p' |
    python3 scripts/deb-depends-from-root.py "$sysroot/var/cache/apt/archives")
else
  shlibs=$(mktemp -d)
  mkdir -p "$shlibs/debian"
  printf 'Source: infotrack\n\nPackage: infotrack\nArchitecture: any\n' >"$shlibs/debian/control"
  depends=$(cd "$shlibs" && DEB_HOST_ARCH="$arch" DEB_HOST_GNU_TYPE="$triplet" \
    DEB_HOST_MULTIARCH="$triplet" dpkg-shlibdeps -O -e"$stage/usr/lib/infotrack/infotrack" \
    -l"$stage/usr/lib/infotrack" 2>/dev/null | sed -n 's/^shlibs:Depends=//p')
  rm -rf "$shlibs"
fi

mkdir -p "$stage/DEBIAN"
size=$(du -sk --exclude=DEBIAN "$stage" | cut -f1)
cat >"$stage/DEBIAN/control" <<CONTROL
Package: infotrack
Version: $version
Architecture: $arch
Maintainer: infotrack maintainers <maintainers@infotrack.invalid>
Installed-Size: $size
Depends: $depends, adduser
Section: science
Priority: optional
Description: find and follow a hidden moving ground target from a drone
 A companion-computer daemon: AprilTag detection, a particle filter with a learned
 motion model (ONNX Runtime, included) and expected-entropy-reduction guidance,
 flying PX4 or ArduPilot through MAVLink offboard or guided setpoints.
CONTROL
(cd "$stage" && find etc -type f | sed 's|^|/|' | sort) >"$stage/DEBIAN/conffiles"
cat >"$stage/DEBIAN/postinst" <<'POSTINST'
#!/bin/sh
set -e
if [ "$1" = configure ]; then
  if ! getent passwd infotrack >/dev/null; then
    adduser --system --group --home /var/lib/infotrack --no-create-home infotrack >/dev/null
  fi
  for g in dialout video; do
    getent group "$g" >/dev/null && adduser infotrack "$g" >/dev/null || true
  done
  mkdir -p /var/lib/infotrack/flights
  chown -R infotrack:infotrack /var/lib/infotrack
  if [ -d /run/systemd/system ]; then
    systemctl daemon-reload || true
    systemctl try-restart infotrack.service || true
  fi
fi
POSTINST
cat >"$stage/DEBIAN/prerm" <<'PRERM'
#!/bin/sh
set -e
# Stopping puts the vehicle in hold when infotrack has it (the unit's SIGTERM).
if [ "$1" = remove ] && [ -d /run/systemd/system ]; then
  systemctl stop infotrack.service || true
fi
PRERM
cat >"$stage/DEBIAN/postrm" <<'POSTRM'
#!/bin/sh
set -e
if [ -d /run/systemd/system ]; then
  systemctl daemon-reload || true
fi
# Purge: the user and its flight logs go too (remove keeps them, and the configs).
if [ "$1" = purge ]; then
  rm -rf /var/lib/infotrack
  if getent passwd infotrack >/dev/null; then
    deluser --system infotrack >/dev/null || true
  fi
fi
POSTRM
chmod 0755 "$stage/DEBIAN/postinst" "$stage/DEBIAN/prerm" "$stage/DEBIAN/postrm"
mkdir -p "$out"
deb="$out/infotrack_${version}_${arch}.deb"
dpkg-deb --build --root-owner-group "${compression[@]}" "$stage" "$deb" >&2
echo "$deb"
