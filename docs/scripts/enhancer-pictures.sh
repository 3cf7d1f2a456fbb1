#!/bin/sh
# The enhancer's pictures, from held-out data only (an LFW identity the preset held out,
# COCO images with id % 5 == 0):
# - docs/img/enhancer.jpg: raw | captured | enhanced for a face and a street scene (README);
# - docs/img/enhancer-grid.jpg: the same for six more COCO images (docs/enhancer.md).
# Usage: docs/scripts/enhancer-pictures.sh [PARAMS] [SHARED]   (from the repository root;
# PARAMS must name an enhancer: campro train-enhancer)
set -eu
params=${1:-params/campro-omega-0.5.json}
shared=${2:-../shared}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
campro=target/release/campro
cargo build --release -q -p campro-cli
coco=$shared/data/coco-person/images
mkdir "$work/raw"
cp "$shared/data/lfw/images_deepfunneled/Jeremy_Greenstock/Jeremy_Greenstock_0001.jpg" "$work/raw/face.jpg"
cp "$coco/000000338625.jpg" "$work/raw/street.jpg"
for id in 000000549930 000000500270 000000210230 000000572900 000000480985 000000074200; do
  cp "$coco/$id.jpg" "$work/raw/$id.jpg"
done
$campro simulate "$params" "$work/raw" -o "$work/captured" --image-format png 2>/dev/null
$campro simulate "$params" "$work/raw" -o "$work/enhanced" --enhance --image-format png 2>/dev/null
# row NAME HEIGHT: raw | captured | enhanced of NAME, HEIGHT pixels high, 4 px apart.
row() {
  ffmpeg -v error -y -i "$work/raw/$1.jpg" -i "$work/captured/$1.png" -i "$work/enhanced/$1.png" -filter_complex \
    "[0]scale=-2:$2,pad=iw+4:ih:0:0:white[a];[1]scale=-2:$2,pad=iw+4:ih:0:0:white[b];[2]scale=-2:$2[c];[a][b][c]hstack=3" \
    "$work/row-$1.png"
}
row face 250
row street 250
ffmpeg -v error -y -i "$work/row-face.png" -i "$work/row-street.png" -filter_complex \
  "[0]scale=960:-2,pad=960:ih+4:0:0:white[a];[1]scale=960:-2[b];[a][b]vstack=2" -q:v 4 docs/img/enhancer.jpg
inputs=""
n=0
for id in 000000549930 000000500270 000000210230 000000572900 000000480985 000000074200; do
  row "$id" 160
  ffmpeg -v error -y -i "$work/row-$id.png" -vf "scale=900:-2,pad=900:ih+4:0:0:white" "$work/grid-$n.png"
  inputs="$inputs -i $work/grid-$n.png"
  n=$((n + 1))
done
# shellcheck disable=SC2086
ffmpeg -v error -y $inputs -filter_complex "vstack=$n" -q:v 4 docs/img/enhancer-grid.jpg
ls -l docs/img/enhancer.jpg docs/img/enhancer-grid.jpg
