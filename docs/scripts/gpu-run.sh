#!/usr/bin/env bash
# Runs on a lent GPU machine, from the repository root, with the pack of
# docs/scripts/gpu-pack.sh carried as gpu-pack/ (no Rust there): checks the device, runs
# the op tests on CUDA, times the training steps on the CPU and on CUDA, and trains
# (resuming from gpu-pack/checkpoints/ when a previous session left one there), writing
# everything into $OUT. `--dry` stops where a GPU is first needed (what can be tested on a
# machine without one).
#
# Usage: bash gpu-pack/run.sh [--dry]
set -uo pipefail
pack=$(cd "$(dirname "$0")" && pwd)
out=${OUT:-$PWD/gpu-out}
mkdir -p "$out"
export CAMPRO_SHARED="$pack/shared"
dry=${1:-}
say() { echo "== $(date +%T) $*" | tee -a "$out/steps.log"; }
# The binaries travel xz-compressed.
bin=$(mktemp -d)
for b in campro ops; do
  xz -dc "$pack/bin/$b.xz" > "$bin/$b" && chmod +x "$bin/$b" || { say "cannot unpack $b (xz missing?)"; exit 1; }
done

say device
if [ "$dry" != --dry ]; then
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$out/device.txt" || {
    say "no GPU: stopping"; exit 1; }
fi
say "op tests (CPU always; CUDA where a GPU is present)"
"$bin/ops" --test-threads 1 --nocapture > "$out/ops.txt" 2>&1
echo "ops exit $?" | tee -a "$out/steps.log"
grep -E "test result|skipped" "$out/ops.txt" | sort | uniq -c | tee -a "$out/steps.log"
say "training steps on the CPU"
"$bin/campro" bench train --shared "$pack/shared" --runs 3 --format json > "$out/bench-cpu.json" 2> "$out/bench-cpu.err"
echo "bench cpu exit $?" | tee -a "$out/steps.log"
if [ "$dry" = --dry ]; then
  say "dry run: stopping before the GPU is needed"
  exit 0
fi
say "training steps on CUDA"
"$bin/campro" bench train --shared "$pack/shared" --runs 3 --device cuda --format json > "$out/bench-cuda.json" 2> "$out/bench-cuda.err"
echo "bench cuda exit $?" | tee -a "$out/steps.log"
say "training on CUDA"
resume=()
[ -d "$pack/checkpoints" ] && resume=(--resume "$pack/checkpoints")
"$bin/campro" train "$pack/train.toml" --device cuda -o "$out/gpu-pack.json" --log "$out/train.csv" \
  --checkpoints "$out/checkpoints" "${resume[@]}" > "$out/train.txt" 2>&1
echo "train exit $?" | tee -a "$out/steps.log"
say done
