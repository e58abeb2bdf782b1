#!/usr/bin/env bash
# sitl-copy.sh SRC DEST: a runnable copy of the SITL builds in SRC (../shared/sitl) at DEST.
# PX4's px4-* command links arrive as 3-byte files saying "px4": they become links again.
set -euo pipefail
src="$1"; copy="$2"
mkdir -p "$copy"
cp -r "$src/." "$copy/"
chmod -R u+w "$copy"
for f in "$copy"/px4/bin/px4-*; do
  [ "$(basename "$f")" = px4-alias.sh ] && continue
  if [ "$(cat "$f")" = px4 ]; then rm -f "$f"; ln -s px4 "$f"; fi
done
