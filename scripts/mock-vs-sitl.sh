#!/usr/bin/env bash
# mock-vs-sitl.sh [FLIGHTS]: the same lab flight (config/default.toml, its seed, 60 s of
# tracking, wall clock) flown FLIGHTS times (default 5) on each SITL build in ../shared/sitl
# and on the in-process mock of the same flavour with daemon.mock_response = "sitl"; prints
# one line per flight and the means (the mock should predict what the SITL flies
# within 10 points of FOV and 30 % of tracking error). Takes ~2 min per flight pair.
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-5}"
src="${INFOTRACK_SITL_SOURCE:-../shared/sitl}"
[ -x "$src/px4/bin/px4" ] || { echo "no SITL builds at $src"; exit 1; }
cargo build --release --quiet
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
bash scripts/sitl-copy.sh "$src" "$tmp/sitl"
lab="$tmp/lab.toml"
printf '%s\n\n[daemon]\ntakeoff_timeout_s = 120.0\nconnect_timeout_s = 60.0\nmock_response = "sitl"\n' \
  "$(cat config/default.toml)" > "$lab"
summary() { python3 -c "import json,sys; s=json.load(open(sys.argv[1])); print(f\"{s['tracking_error_m']:.3f} {s['fov_percent']:.1f}\")" "$1/summary.json"; }
fly() { # fly NAME VEHICLE
  ./target/release/infotrack run --quiet --allow-simulation-on-vehicle --allow-auto-engage --vehicle "$2" --duration 60 --config "$lab" --out "$tmp/$1" \
    > "$tmp/$1.log" 2>&1 || { echo "$1 failed:"; tail -5 "$tmp/$1.log"; return 1; }
  echo "$1 $(summary "$tmp/$1")" | tee -a "$tmp/results"
}
sitl() { # sitl NAME px4|arducopter
  local work="$tmp/$1-work" pid url
  if [ "$2" = px4 ]; then
    "$tmp/sitl/px4/start.sh" "$work" 0 > "$tmp/$1-console.log" 2>&1 & pid=$!; url=udpin:127.0.0.1:14540
  else
    "$tmp/sitl/arducopter/start.sh" "$work" 1 serial0=tcp:0 > "$tmp/$1-console.log" 2>&1 & pid=$!; url=tcpout:127.0.0.1:5772
  fi
  sleep 3
  fly "$1" "$url" || true
  kill -TERM "$pid" 2>/dev/null || true; sleep 3; pkill -f "$work" 2>/dev/null || true; sleep 1
}
for k in $(seq "$n"); do
  sitl "sitl-px4-$k" px4
  sitl "sitl-arducopter-$k" arducopter
  fly "mock-px4-$k" mock:px4
  fly "mock-ardupilot-$k" mock:ardupilot
done
python3 - "$tmp/results" <<'PY'
import sys, statistics as st, collections
rows = collections.defaultdict(list)
for line in open(sys.argv[1]):
    name, track, fov = line.split()
    rows[name.rsplit("-", 1)[0]].append((float(track), float(fov)))
for name, v in sorted(rows.items()):
    t = [a for a, _ in v]; f = [b for _, b in v]
    print(f"{name:16s} {len(v)} flights: tracking {st.mean(t):.3f} m, FOV {st.mean(f):.1f} %")
PY
