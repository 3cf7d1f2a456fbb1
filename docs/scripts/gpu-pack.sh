#!/usr/bin/env bash
# Builds campro with CUDA on this machine (no GPU needed) and packs what a lent GPU machine
# needs into gpu-pack/ (under 64 MiB: the device tool carries at most that): the CUDA
# binary, the op tests built for CUDA, a small copy of the shared data (the four models, a
# subset of LFW's identities with >= 5 photos, a subset of the COCO person images with
# their annotations) and a short training configuration. docs/gpu.md says how to run it.
#
# Usage: docs/scripts/gpu-pack.sh [LFW_IDENTITIES [COCO_IMAGES]]   (defaults 60 and 150)
# Needs: Python 3 with venv and pip (nvcc comes from PyPI), $CAMPRO_SHARED or ../shared.
set -euo pipefail
cd "$(dirname "$0")/../.."
ids=${1:-60}
coco=${2:-150}
shared=${CAMPRO_SHARED:-../shared}
venv=target/cuda/venv
# nvcc, the CUDA runtime headers and the C runtime headers, pinned (CUDA 13, the lent
# machines' libraries).
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q nvidia-cuda-nvcc==13.5.37 nvidia-cuda-runtime nvidia-cuda-crt nvidia-cuda-cccl
fi
cuda=$(echo "$venv"/lib/python3*/site-packages/nvidia/cu13)
export CUDA_ROOT="$PWD/$cuda" CUDA_PATH="$PWD/$cuda" PATH="$PWD/$cuda/bin:$PATH"
# H100 and H200 are compute capability 9.0; there is no GPU here to ask.
export CUDA_COMPUTE_CAP=${CUDA_COMPUTE_CAP:-90}
# candle's kernels link the CUDA runtime: its static library (the wheel has no libcudart.so),
# found through the C compiler's LIBRARY_PATH so that no RUSTFLAGS change rebuilds the rest.
mkdir -p target/cuda/link
ln -sf "$PWD/$cuda/lib/libcudart_static.a" target/cuda/link/libcudart.a
export LIBRARY_PATH="$PWD/target/cuda/link${LIBRARY_PATH:+:$LIBRARY_PATH}"
cargo build --release --locked -p campro-cli --features cuda --target-dir target/cuda
ops=$(cargo test --release --locked -p campro-nn --features cuda --test ops --no-run --target-dir target/cuda \
  --message-format=json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "ops" and m.get("executable"):
        print(m["executable"])')
pack=gpu-pack
rm -rf "$pack.part" && mkdir -p "$pack.part/bin" "$pack.part/shared/models" "$pack.part/shared/data"
# Stripped and xz-compressed (76 MB of campro, most of it candle's CUDA kernels as PTX,
# become about 16 MB); run.sh unpacks them.
for b in campro ops; do
  src=target/cuda/release/campro
  [ "$b" = ops ] && src=$ops
  strip -o "$pack.part/bin/$b" "$src"
  xz -T2 -6 "$pack.part/bin/$b"
done
# What training and its bench read: YuNet (face alignment), the attacker's checkpoint,
# YOLOX-Nano (the utility player).
cp "$shared"/models/{yunet_s_640_640.onnx,mobilefacenet_casia_068.ckpt,yolox_nano.onnx,README.md} "$pack.part/shared/models/"
python3 - "$shared" "$pack.part/shared" "$ids" "$coco" <<'PY'
import json, os, shutil, sys
src, dst, ids, coco = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
lfw = os.path.join(src, "data/lfw")
out = os.path.join(dst, "data/lfw")
os.makedirs(os.path.join(out, "images_deepfunneled"))
# The first identities (by name) with at least 5 photos, every photo of each.
people = sorted(p for p in os.listdir(os.path.join(lfw, "images_deepfunneled"))
                if len(os.listdir(os.path.join(lfw, "images_deepfunneled", p))) >= 5)[:ids]
for p in people:
    shutil.copytree(os.path.join(lfw, "images_deepfunneled", p), os.path.join(out, "images_deepfunneled", p))
for f in ("pairs.txt", "lfw-names.txt", "README.txt"):
    if os.path.exists(os.path.join(lfw, f)):
        shutil.copy(os.path.join(lfw, f), out)
# The first COCO person images by id, with their annotations and labels.
cs, co = os.path.join(src, "data/coco-person"), os.path.join(dst, "data/coco-person")
os.makedirs(os.path.join(co, "images")); os.makedirs(os.path.join(co, "labels"))
d = json.load(open(os.path.join(cs, "instances_person.json")))
keep = sorted(d["images"], key=lambda im: im["id"])[:coco]
ids_kept = {im["id"] for im in keep}
json.dump({"images": keep, "annotations": [a for a in d["annotations"] if a["image_id"] in ids_kept],
           "categories": d["categories"]}, open(os.path.join(co, "instances_person.json"), "w"))
for im in keep:
    shutil.copy(os.path.join(cs, "images", im["file_name"]), os.path.join(co, "images"))
    label = os.path.splitext(im["file_name"])[0] + ".txt"
    if os.path.exists(os.path.join(cs, "labels", label)):
        shutil.copy(os.path.join(cs, "labels", label), os.path.join(co, "labels"))
print(f"pack: {len(people)} LFW identities, {len(keep)} COCO images")
PY
cp docs/scripts/gpu-run.sh "$pack.part/run.sh"
cp crates/campro-train/configs/gpu-pack.toml "$pack.part/train.toml"
size=$(du -sb "$pack.part" | cut -f1)
echo "pack: $((size / 1048576)) MiB in $pack/"
if [ "$size" -gt $((64 << 20)) ]; then
  echo "pack: over the device tool's 64 MiB; use fewer identities or images" >&2
  exit 1
fi
rm -rf "$pack" && mv "$pack.part" "$pack"
