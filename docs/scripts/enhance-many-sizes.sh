#!/usr/bin/env bash
# Peak memory (GNU time's maximum resident set) of `campro simulate --enhance` over a folder
# of photos that all differ in size (the enhancer and the guard's detectors are planned
# once a size; issue 78 measured 1,137 MB over 780 such photos before plans were bounded).
# Usage: docs/scripts/enhance-many-sizes.sh [N=300] [path/to/campro]   (needs ffmpeg)
set -euo pipefail
n="${1:-300}"
campro="${2:-target/release/campro}"
d="$(mktemp -d)"; trap 'rm -rf "$d"' EXIT
mkdir "$d/in"
for k in $(seq 0 $((n - 1))); do
  # Widths 112..640 and heights 96..480 in steps of 16 (the enhancer's multiple), so that
  # every photo pads to its own size.
  w=$((112 + (k % 34) * 16)); h=$((96 + (k / 34 % 25) * 16))
  ffmpeg -hide_banner -v error -nostdin -y -f lavfi -i "testsrc2=size=${w}x${h}:rate=1" \
    -frames:v 1 -q:v 3 "$d/in/p$k.jpg"
done
/usr/bin/time -v -o "$d/time" "$campro" simulate campro-omega-0.5 "$d/in" -o "$d/out" --enhance >/dev/null
printf '%s photos of distinct sizes: %s s, peak %s MiB\n' "$n" \
  "$(awk -F': ' '/Elapsed/ {print $2}' "$d/time")" \
  "$(awk -F: '/Maximum resident/ {print int($2 / 1024)}' "$d/time")"
