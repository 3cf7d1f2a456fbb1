#!/usr/bin/env bash
# The enhancer at 720p: frames a second and quality, full resolution against the reduced
# network (--enhance-scale 2, what auto picks from 1280x720), side by side in one run, with
# the camera alone as the anchor.
#
# Speed: a generated 1280x720 clip of 60 frames through `campro simulate` (camera alone,
# --enhance-scale 1, --enhance-scale 2); the summary line's "frames a second" is the whole
# run's (decode, camera, enhancer, H.264 encode). Quality: the first N held-out COCO images
# (id a multiple of 5, never trained on; about 416 pixels wide in ../shared) upscaled to
# 1280 wide (lanczos: the size of a 720p frame, but smoother than a camera's) as the raw
# images, through the camera and the enhancer at each scale; PSNR
# and SSIM against the raw image (ffmpeg's psnr and ssim filters, on RGB), averaged. The
# other end, the network seeing a scene half the size it was trained on: `campro eval
# quality PRESET --enhanced --held-out --enhance-scale 2` against `--enhance-scale 1`.
#
# Usage: docs/scripts/enhancer-speed.sh [PRESET] [N]   (default campro-omega-0.5, 40)
# Needs: a release build (cargo build --release -p campro-cli), ffmpeg, ../shared.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
campro="$root/target/release/campro"
preset="${1:-campro-omega-0.5}"
n="${2:-40}"
shared="${CAMPRO_SHARED:-$root/../shared}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

ffmpeg -hide_banner -v error -f lavfi -i testsrc2=size=1280x720:rate=30 -t 2 -c:v libx264 "$work/clip.mp4"
echo "| 1280x720, 60 frames | frames a second (whole run) |"
echo "|---|---|"
for mode in camera 1 2; do
  args=(); [ "$mode" != camera ] && args=(--enhance --enhance-scale "$mode")
  line="$("$campro" simulate "$preset" "$work/clip.mp4" -o "$work/v-$mode" "${args[@]}" 2>&1 | grep '^simulated')"
  fps="$(sed -E 's/.*\(([0-9.]+) frames a second.*/\1/' <<<"$line")"
  label="camera alone"; [ "$mode" != camera ] && label="camera + enhancer at scale $mode"
  echo "| $label | $fps |"
done

mkdir -p "$work/raw"
k=0
for path in "$shared"/data/coco-person/images/*.jpg; do
  f="$(basename "$path")"; id="${f%.jpg}"
  [ $((10#$id % 5)) -eq 0 ] || continue
  k=$((k + 1)); [ "$k" -le "$n" ] || break
  ffmpeg -hide_banner -v error -i "$shared/data/coco-person/images/$f" -vf "scale=1280:-2:flags=lanczos" "$work/raw/${f%.jpg}.png"
done
echo
echo "| $n held-out COCO images at 1280 wide | PSNR (dB) | SSIM | seconds |"
echo "|---|---|---|---|"
for s in 1 2; do
  t0=$(date +%s.%N)
  "$campro" simulate "$preset" "$work/raw" -o "$work/s$s" --enhance --enhance-scale "$s" 2>/dev/null
  t1=$(date +%s.%N)
  psnr=0; ssim=0; k=0
  for raw in "$work/raw"/*.png; do
    out="$work/s$s/$(basename "$raw")"
    p="$(ffmpeg -hide_banner -i "$out" -i "$raw" -lavfi "[0:v]format=gbrp[a];[1:v]format=gbrp[b];[a][b]psnr" -f null - 2>&1 | sed -nE 's/.*average:([0-9.inf]+).*/\1/p')"
    q="$(ffmpeg -hide_banner -i "$out" -i "$raw" -lavfi "[0:v]format=gbrp[a];[1:v]format=gbrp[b];[a][b]ssim" -f null - 2>&1 | sed -nE 's/.*All:([0-9.]+).*/\1/p')"
    psnr=$(echo "$psnr + $p" | bc -l); ssim=$(echo "$ssim + $q" | bc -l); k=$((k + 1))
  done
  printf "| enhancer at scale %s | %.2f | %.3f | %.1f |\n" "$s" "$(echo "$psnr / $k" | bc -l)" "$(echo "$ssim / $k" | bc -l)" "$(echo "$t1 - $t0" | bc -l)"
done
