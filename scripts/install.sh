#!/usr/bin/env bash
# Installs infotrack as a service on this companion computer, in one command:
#   sudo bash scripts/install.sh
# What goes where:
#   /usr/local/lib/infotrack/infotrack            the program, and beside it
#   /usr/local/lib/infotrack/libonnxruntime.so.*  ONNX Runtime (found there; no .deps needed)
#   /usr/local/bin/infotrack                      a link to the program
#   /etc/infotrack/config/, /etc/infotrack/models/ the configs and models (a config's paths are
#                                                  relative to it: px4.toml finds
#                                                  ../models/outdoor/dmmn.onnx); files you
#                                                  edited are kept, the new ones written as *.new
#   /var/lib/infotrack/flights/                    one folder of logs per flight
#   /etc/systemd/system/infotrack.service          runs as the user `infotrack` (groups dialout
#                                                  and video: the serial port and the camera)
# Options:
#   --destdir DIR   install under DIR instead of / (packaging, tests); no user, no systemctl
#   --binary FILE   install this infotrack binary instead of building one
#   --onnxruntime FILE  the ONNX Runtime library to install beside it (default: the one
#                   scripts/setup.sh puts in .deps/onnxruntime; the arm64 package's own)
#   --config NAME   the config the service runs (default px4.toml; ardupilot.toml for ArduPilot)
#   --prefix DIR    the program under DIR/lib/infotrack and DIR/bin (default /usr/local;
#                   scripts/build-deb.sh packages with /usr)
#   --files-only    install the files only: no user, no systemctl (a package's postinst does
#                   those)
# Then: edit /etc/infotrack/config/<config> (vehicle URL, camera, calibration), and
#   systemctl enable --now infotrack; journalctl -u infotrack -f
set -euo pipefail
cd "$(dirname "$0")/.."

destdir=""
binary=""
config="px4.toml"
prefix="/usr/local"
files_only=""
ort=""
while [ $# -gt 0 ]; do
  case "$1" in
    --destdir) destdir="$2"; shift 2 ;;
    --binary) binary="$2"; shift 2 ;;
    --onnxruntime) ort="$2"; shift 2 ;;
    --config) config="$2"; shift 2 ;;
    --prefix) prefix="$2"; shift 2 ;;
    --files-only) files_only=1; shift ;;
    *) echo "install: unknown option $1 (--destdir DIR, --binary FILE, --onnxruntime FILE, --config NAME, --prefix DIR, --files-only)" >&2; exit 2 ;;
  esac
done
[ -f "config/$config" ] || { echo "install: config/$config does not exist" >&2; exit 2; }

bash scripts/setup.sh
if [ -z "$binary" ]; then
  cargo build --release --locked --bin infotrack
  binary=target/release/infotrack
fi
[ -x "$binary" ] || { echo "install: $binary is not an executable" >&2; exit 2; }
[ -n "$ort" ] || ort=$(ls .deps/onnxruntime/libonnxruntime.so.* | head -n 1)
[ -f "$ort" ] || { echo "install: no ONNX Runtime library at $ort" >&2; exit 2; }

lib="$destdir$prefix/lib/infotrack"
etc="$destdir/etc/infotrack"
var="$destdir/var/lib/infotrack"
install -d "$lib" "$destdir$prefix/bin" "$etc" "$var/flights" "$destdir/etc/systemd/system"
install -m 0755 "$binary" "$lib/infotrack"
install -m 0644 "$ort" "$lib/"
ln -sfn ../lib/infotrack/infotrack "$destdir$prefix/bin/infotrack"

# Configs and models: never overwrite what the operator changed.
copy_kept() {
  local src="$1" dst="$2"
  install -d "$(dirname "$dst")"
  if [ -f "$dst" ] && ! cmp -s "$src" "$dst"; then
    install -m 0644 "$src" "$dst.new"
    echo "install: kept your $dst; the shipped one is $dst.new" >&2
  else
    install -m 0644 "$src" "$dst"
  fi
}
while IFS= read -r f; do copy_kept "$f" "$etc/$f"; done < <(find config models -type f \
  \( -name '*.toml' -o -name '*.yaml' -o -name '*.onnx' -o -name '*.json' -o -name '*.geojson' \
  -o -name 'README.md' \) | sort)

unit_dir="$destdir/etc/systemd/system"
# A package's unit belongs under /lib/systemd/system (the operator's overrides go in /etc).
[ "$prefix" = "/usr" ] && unit_dir="$destdir/lib/systemd/system" && install -d "$unit_dir"
sed -e "s|/etc/infotrack/config/px4.toml|/etc/infotrack/config/$config|" \
  -e "s|/usr/local/bin/infotrack|$prefix/bin/infotrack|" \
  config/infotrack.service > "$unit_dir/infotrack.service"

if [ -n "$files_only" ]; then
  echo "install: files done under ${destdir:-/}" >&2
elif [ -z "$destdir" ]; then
  if ! id infotrack >/dev/null 2>&1; then
    useradd --system --home-dir /var/lib/infotrack --shell /usr/sbin/nologin infotrack
  fi
  for g in dialout video; do getent group "$g" >/dev/null && usermod -aG "$g" infotrack; done
  chown -R infotrack:infotrack /var/lib/infotrack
  if [ -d /run/systemd/system ]; then
    systemctl daemon-reload
    echo "install: done; start it with: systemctl enable --now infotrack" >&2
  else
    echo "install: done; systemd is not running here, start it by hand:" >&2
    echo "  sudo -u infotrack /usr/local/bin/infotrack run --config /etc/infotrack/config/$config --duration 0 --log-dir /var/lib/infotrack/flights" >&2
  fi
else
  echo "install: done under $destdir" >&2
fi
