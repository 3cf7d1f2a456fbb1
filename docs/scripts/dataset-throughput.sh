#!/usr/bin/env bash
# The measured rows of docs/datasets.md: images a second for `campro simulate` and for the
# Ray job with 1 and 2 actors, in one run, on N 1920x1080 JPEGs tiled from COCO photos.
# Needs the wheel and Ray in the Python that runs it (pip install campro-*.whl 'ray[data]')
# and ../shared (or $CAMPRO_SHARED). Usage: N=200 PRESET=campro-omega-0.5 bash docs/scripts/dataset-throughput.sh
set -euo pipefail
N=${N:-200}
PRESET=${PRESET:-campro-omega-0.5}
PY=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$PY" - "$work/src" "$N" <<'PY'
import os, pathlib, sys
import numpy as np
import campro
src, n = pathlib.Path(sys.argv[1]), int(sys.argv[2])
shared = pathlib.Path(os.environ.get("CAMPRO_SHARED") or pathlib.Path.cwd().parent / "shared")
photos = sorted((shared / "data/coco-person/images").glob("*.jpg"))
cam = campro.Camera("campro-omega-0.5")
made = 0
for p in photos:
    img = campro.read(p)
    try:
        cam.capture(img)  # colour photos only: grey ones are refused
    except campro.Error:
        continue
    reps = (-(-1080 // img.shape[0]), -(-1920 // img.shape[1]), 1)
    frame = np.ascontiguousarray(np.tile(img, reps)[:1080, :1920])
    campro.write(src / f"{made:05d}.jpg", frame, quality=90)
    made += 1
    if made == n:
        break
PY
row() { printf '| %s | %d | %.1f s | %.1f | %s |\n' "$1" "$N" "$2" "$(echo "$N / $2" | bc -l)" "$3"; }
echo "| run | images | wall | images a second (wall) | images a second (the job's own clock) |"
echo "|---|---|---|---|---|"
t0=$(date +%s.%N); campro simulate "$PRESET" "$work/src" -o "$work/simulate" --record 2>/dev/null; t1=$(date +%s.%N)
row "campro simulate --record (every core)" "$(echo "$t1 - $t0" | bc -l)" "-"
for actors in 1 2; do
  t0=$(date +%s.%N)
  summary=$("$PY" -m campro.ray protect "$work/src" "$work/ray$actors" --preset "$PRESET" --concurrency "$actors" 2>/dev/null)
  t1=$(date +%s.%N)
  own=$(echo "$summary" | sed -n 's/.*; \([0-9.]*\) images a second.*/\1/p')
  row "python -m campro.ray protect, $actors actor(s) (wall: Ray's start included)" "$(echo "$t1 - $t0" | bc -l)" "$own"
  cmp -s <(cd "$work/simulate" && find . -type f ! -name '*.campro.json' -exec sha256sum {} + | sort) \
         <(cd "$work/ray$actors" && find . -type f ! -name '*.campro.json' -exec sha256sum {} + | sort) \
    || { echo "the Ray outputs differ from simulate's" >&2; exit 1; }
done
