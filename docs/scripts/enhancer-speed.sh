#!/usr/bin/env bash
# The enhancer on video: frames a second at 720p and 1080p beside the anchors of the same
# run (a plain ffmpeg re-encode, the camera alone), then quality at 720p, full resolution
# against the reduced network (--enhance-scale 2, what auto picks from 1280x720).
#
# Speed: a generated clip of 60 frames (testsrc2) at each size through `ffmpeg -c:v libx264
# -crf 18` (the anchor: decode and the same encode), `campro simulate` (camera alone) and
# `campro simulate --enhance` (the network at auto scale and the face guard over the
# enhanced and captured frames: what a person is shown), plus --enhance-scale 1 at 720p; the
# summary line's "frames a second" is the whole run's (decode, camera, enhancer, guard,
# H.264 encode), and the peak resident memory is /usr/bin/time's; then 4 frames of 4K for the
# peak memory there. Quality: the first N
# held-out COCO images (id a multiple of 5, never trained on; about 416 pixels wide in
# ../shared) upscaled to 1280 wide (lanczos: the size of a 720p frame, but smoother than a
# camera's) as the raw images, through the camera and the enhancer at each scale; PSNR and
# SSIM against the raw image (ffmpeg's psnr and ssim filters, on RGB), averaged. The other
# end, the network seeing a scene half the size it was trained on: `campro eval quality
# PRESET --enhanced --held-out --enhance-scale 2` against `--enhance-scale 1`.
#
# Usage: docs/scripts/enhancer-speed.sh [PRESET] [N]   (default campro-omega-0.5, 40; N = 0
# times only)
# Needs: a release build (cargo build --release -p campro-cli), ffmpeg, GNU time, ../shared.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
campro="$root/target/release/campro"
preset="${1:-campro-omega-0.5}"
n="${2:-40}"
shared="${CAMPRO_SHARED:-$root/../shared}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

echo "| 60 frames | frames a second (whole run) | peak memory (MB) |"
echo "|---|---|---|"
for size in 1280x720 1920x1080; do
  clip="$work/clip-$size.mp4"
  ffmpeg -hide_banner -v error -f lavfi -i "testsrc2=size=$size:rate=30" -t 2 -c:v libx264 "$clip"
  modes=(ffmpeg camera auto); [ "$size" = 1280x720 ] && modes+=(1)
  for mode in "${modes[@]}"; do
    out="$work/v-$size-$mode"
    t0=$(date +%s.%N)
    if [ "$mode" = ffmpeg ]; then
      /usr/bin/time -f "%M" -o "$work/mem" ffmpeg -hide_banner -v error -i "$clip" -c:v libx264 -crf 18 "$out.mp4"
      fps="$(echo "60 / ($(date +%s.%N) - $t0)" | bc -l)"
      label="ffmpeg re-encode (H.264 CRF 18)"
    else
      args=(); [ "$mode" != camera ] && args=(--enhance --enhance-scale "$mode")
      line="$(/usr/bin/time -f "%M" -o "$work/mem" "$campro" simulate "$preset" "$clip" -o "$out" "${args[@]}" 2>&1 | grep '^simulated')"
      fps="$(sed -E 's/.*\(([0-9.]+) frames a second.*/\1/' <<<"$line")"
      label="campro: camera alone"; [ "$mode" != camera ] && label="campro: camera + enhancer (scale $mode) + face guard"
    fi
    printf "| %s, %s | %.1f | %d |\n" "$size" "$label" "$fps" "$(( $(cat "$work/mem") / 1024 ))"
  done
done
# 4K: memory (the issue's 1 GB) on a short clip; frames a second from 4 frames only.
clip="$work/clip-4k.mp4"
ffmpeg -hide_banner -v error -f lavfi -i "testsrc2=size=3840x2160:rate=30" -frames:v 4 -c:v libx264 "$clip"
line="$(/usr/bin/time -f "%M" -o "$work/mem" "$campro" simulate "$preset" "$clip" -o "$work/v-4k" --enhance 2>&1 | grep '^simulated')"
fps="$(sed -E 's/.*\(([0-9.]+) frames a second.*/\1/' <<<"$line")"
printf "| 3840x2160 (4 frames), campro: camera + enhancer (scale auto) + face guard | %.2f | %d |\n" "$fps" "$(( $(cat "$work/mem") / 1024 ))"
[ "$n" -gt 0 ] || exit 0

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
