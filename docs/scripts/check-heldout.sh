#!/usr/bin/env bash
# `campro check` on 50 held-out LFW identities (the first 50 of campro-omega-0.5's
# provenance.data.validation_identities with 2 or more photos, their first 2 photos: 100
# photos), for every bundled preset and the identity camera; JSON reports into OUT.
# Usage: bash docs/scripts/check-heldout.sh OUT   (SHARED: $CAMPRO_SHARED or ../shared)
set -euo pipefail
out="${1:?usage: check-heldout.sh OUT}"
shared="${CAMPRO_SHARED:-../shared}"
photos="$out/photos"
mkdir -p "$photos"
python3 - "$shared" "$photos" <<'PY'
import json, os, shutil, sys
shared, photos = sys.argv[1:]
ids = json.load(open("params/campro-omega-0.5.json"))["provenance"]["data"]["validation_identities"]
lfw = os.path.join(shared, "data/lfw/images_deepfunneled")
n = 0
for name in ids:
    files = sorted(os.listdir(os.path.join(lfw, name)))
    if len(files) < 2:
        continue
    os.makedirs(os.path.join(photos, name), exist_ok=True)
    for f in files[:2]:
        shutil.copy(os.path.join(lfw, name, f), os.path.join(photos, name, f))
    n += 1
    if n == 50:
        break
PY
for preset in campro-omega-0.5 campro-omega-0.5-hour campro-omega-0.5-distill campro-omega-1 campro-omega-1-shared-continued campro-omega-5 params/identity.json; do
  name=$(basename "$preset" .json)
  /usr/bin/time -f "$name: %e s, %M KB" ./target/release/campro check "$preset" "$photos" --format json > "$out/$name.json"
done
