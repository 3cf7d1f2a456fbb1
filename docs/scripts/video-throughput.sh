#!/bin/sh
# Video throughput: campro simulate against ffmpeg's lut3d and haldclut on the same 1080p30
# H.264 clip, and the decode / encode split. Prints a Markdown table (fps = frames / wall s).
# Usage: docs/scripts/video-throughput.sh [PARAMS] [SECONDS]   (from the repository root)
set -eu
params=${1:-params/campro-omega-0.5.json}
secs=${2:-10}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
campro=target/release/campro
cargo build --release -q -p campro-cli
ffmpeg -v error -f lavfi -i "testsrc2=size=1920x1080:rate=30" -f lavfi -i "sine=frequency=440:sample_rate=48000" \
  -t "$secs" -c:v libx264 -crf 18 -pix_fmt yuv420p -c:a aac "$work/in.mp4"
frames=$((secs * 30))
$campro convert "$params" --target cube --cube-size 33 -o "$work/c33.cube"
$campro convert "$params" --target cube --cube-size 65 -o "$work/c65.cube"
$campro convert "$params" --target hald --hald-level 8 -o "$work/h8.ppm"
$campro convert "$params" --target hald --hald-level 16 -o "$work/h16.ppm"
# fps of a command that processes the clip.
fps() {
  start=$(date +%s.%N)
  "$@" >/dev/null 2>&1
  end=$(date +%s.%N)
  echo "$frames / ($end - $start)" | bc -l | xargs printf '%.1f'
}
echo "| what | x264 preset medium (default) | x264 preset ultrafast |"
echo "|---|---|---|"
# row NAME FUNCTION ARGS...: FUNCTION PRESET ARGS... with both presets.
row() {
  name=$1; fn=$2; shift 2
  echo "| $name | $(fps "$fn" medium "$@") fps | $(fps "$fn" ultrafast "$@") fps |"
}
# ff PRESET FFMPEG-INPUT-AND-FILTER-ARGS...: ffmpeg to H.264 CRF 18, audio copied.
ff() {
  preset=$1; shift
  rm -f "$work/o.mp4"
  ffmpeg -v error -y "$@" -c:v libx264 -crf 18 -preset "$preset" -c:a copy "$work/o.mp4"
}
# simulate PRESET: campro simulate with its defaults (libx264, CRF 18).
simulate() {
  rm -rf "$work/out"
  $campro simulate "$params" "$work/in.mp4" -o "$work/out" --preset "$1"
}
# pipes PRESET: what campro simulate does without campro (decode to RGB on a pipe, encode).
pipes() {
  ffmpeg -v error -i "$work/in.mp4" -f rawvideo -pix_fmt rgb24 - |
    ffmpeg -v error -y -f rawvideo -pix_fmt rgb24 -s 1920x1080 -framerate 30 -i - \
      -c:v libx264 -crf 18 -preset "$1" -pix_fmt yuv420p "$work/o.mp4"
}
echo "| decode only (ffmpeg -f null) | $(fps ffmpeg -v error -i "$work/in.mp4" -f null -) fps | |"
row "decode + encode (no filter)" ff -i "$work/in.mp4"
row "decode to RGB pipe + encode from it (campro's plumbing, no campro)" pipes
row "campro simulate (exact)" simulate
row "ffmpeg lut3d, 33-point cube" ff -i "$work/in.mp4" -vf "lut3d=$work/c33.cube"
row "ffmpeg lut3d, 65-point cube" ff -i "$work/in.mp4" -vf "lut3d=$work/c65.cube"
row "ffmpeg haldclut, level 8" ff -i "$work/in.mp4" -i "$work/h8.ppm" -filter_complex "[0][1]haldclut"
row "ffmpeg haldclut, level 16" ff -i "$work/in.mp4" -i "$work/h16.ppm" -filter_complex "[0][1]haldclut"
