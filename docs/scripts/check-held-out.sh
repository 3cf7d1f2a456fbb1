#!/usr/bin/env bash
# `campro check` on held-out LFW identities, for every bundled preset: the table of
# trained/README.md ("campro check on held-out identities").
#
# The photos: the first N (default 50) of `campro-omega-0.5`'s held-out identities
# (provenance.data.validation_identities, never trained on) in name order that have at least
# two LFW photos, their first two photos each (100 photos), one folder a person. Each preset
# is checked with the defaults (YuNet, faceplugin and mobilefacenet-casia, 1,000 LFW
# distractors, every view the preset has); per view the table gives the faces, those linkable
# at FAR 1e-3 and 1e-2 on any model, the median and worst over faces of the highest
# similarity over models, and the faces whose true person ranks first. The time and peak
# memory of each run are /usr/bin/time's.
#
# Usage: [PRESETS="a b …"] [KEEP=DIR] [MODELS=DIR] [VIEWS="captured …"] [GRIDS="exact q10 …"]
#        docs/scripts/check-held-out.sh [N]
#   PRESETS: the presets to check (default: every bundled one); KEEP: a folder that keeps each
#   preset's report (`campro check -o`: check.csv, check.json, the HTML page) as DIR/PRESET.
#   MODELS: the models folder (`--models`; e.g. the data folder `campro models fetch` fills,
#   for the default set: CenterFace and faceplugin), else SHARED/models. VIEWS: `--view`s.
#   GRIDS: check each preset as a phone's HAL applies it (the "grid" column; docs/android.md,
#   "Grids"): `exact` (the device transform below, values as sent), `q10`/`q7` (matrix entries
#   rounded to 10 or 7 fractional bits), `lut17`/`lut33`/`lut64` (the curve resampled to that
#   many points); the device transform is DEVICE_CCM (nine numbers; default a phone's auto-mode
#   transform, the Android tests' Fixtures.PHONE). Without GRIDS: the ideal camera, as before.
# Needs: a release build (cargo build --release -p campro-cli), python3, GNU time, ../shared
# (or CAMPRO_SHARED) with data/lfw.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
campro="$root/target/release/campro"
n="${1:-50}"
shared="${CAMPRO_SHARED:-$root/../shared}"
export CAMPRO_SHARED="$shared"
presets="${PRESETS:-$("$campro" presets --format json | python3 -c 'import json, sys; print(" ".join(p["name"] for p in json.load(sys.stdin)))')}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

python3 - "$root/params/campro-omega-0.5.json" "$shared/data/lfw/images_deepfunneled" "$work/photos" "$n" <<'PY'
import json, os, shutil, sys
params, lfw, out, n = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
ids = json.load(open(params))["provenance"]["data"]["validation_identities"]
kept = 0
for name in sorted(ids):
    d = os.path.join(lfw, name)
    files = sorted(os.listdir(d))[:2] if os.path.isdir(d) else []
    if len(files) < 2:
        continue
    os.makedirs(os.path.join(out, name))
    for f in files:
        shutil.copyfile(os.path.join(d, f), os.path.join(out, name, f))
    kept += 1
    if kept == n:
        break
print(f"{kept} identities, {2 * kept} photos", file=sys.stderr)
PY

device_ccm="${DEVICE_CCM:-1.78 -0.62 -0.16 -0.28 1.62 -0.34 0.02 -0.71 1.69}"
grid_flags() {
  case "$1" in
    ideal) ;;
    exact) echo "--device-ccm $device_ccm" ;;
    q[0-9]*) echo "--device-ccm $device_ccm --matrix-frac-bits ${1#q}" ;;
    lut[0-9]*) echo "--device-ccm $device_ccm --lut-size ${1#lut}" ;;
    *) echo "GRIDS: unknown grid $1 (exact, qN, lutN)" >&2; exit 2 ;;
  esac
}
views=""
for v in ${VIEWS:-}; do views="$views --view $v"; done

echo "| preset | grid | view | faces | linkable at 1e-3 | at 1e-2 | median similarity | worst | rank 1 |"
echo "|---|---|---|---|---|---|---|---|---|"
for preset in $presets; do
 for grid in ${GRIDS:-ideal}; do
  run="$preset${GRIDS:+-$grid}"
  # shellcheck disable=SC2046 # the flags are words
  /usr/bin/time -f "$run: %e s, %M KB" -a -o "$work/times" \
    "$campro" check "$preset" --people "$work/photos" -o "$work/report-$run" ${MODELS:+--models "$MODELS"} $views $(grid_flags "$grid") > "$work/lines-$run" 2>&1
  python3 - "$preset" "$grid" "$work/report-$run/check.csv" <<'PY'
import collections, csv, statistics, sys
preset, grid, path = sys.argv[1], sys.argv[2], sys.argv[3]
faces = collections.defaultdict(lambda: collections.defaultdict(list))
for r in csv.DictReader(open(path)):
    faces[r["view"]][(r["photo"], r["face"])].append(r)
for view, by_face in faces.items():
    worst = [max(float(x["similarity"]) for x in rs) for rs in by_face.values()]
    l3 = sum(any(x["linkable_far_1e-3"] == "true" for x in rs) for rs in by_face.values())
    l2 = sum(any(x["linkable_far_1e-2"] == "true" for x in rs) for rs in by_face.values())
    r1 = sum(any(x["rank"] == "1" for x in rs) for rs in by_face.values())
    print(f"| {preset} | {grid} | {view} | {len(by_face)} | {l3} | {l2} | {statistics.median(worst):.2f} | {max(worst):.2f} | {r1} |")
PY
 done
done
runs=""
for preset in $presets; do for grid in ${GRIDS:-ideal}; do runs="$runs $preset${GRIDS:+-$grid}"; done; done
if [ -n "${KEEP:-}" ]; then
  mkdir -p "$KEEP"
  for run in $runs; do cp -r "$work/report-$run" "$KEEP/$run"; done
fi
echo
echo "Summary lines:"
for run in $runs; do
  echo "- $run: $(grep -E 'faces linkable|face linkable' "$work/lines-$run" | tail -1)"
done
echo
cat "$work/times"
