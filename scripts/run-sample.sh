#!/usr/bin/env bash
# The README's main command: install what is missing, build, and run the whole pipeline on the
# bundled sample (samples/explode, an OBJ sequence): import -> resample -> optimize -> export ->
# trace every frame (on the GPU when the CUDA runtime is built and a GPU is present, else the CPU).
# Outputs go to out/sample/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh release
tsah=build/release/apps/tsah
sample=samples/explode
out=out/sample
rm -rf "$out"
mkdir -p "$out"

echo "== 1. import the bundled sample (an OBJ sequence)"
$tsah info "$sample"

echo; echo "== 2. resample it into 5 representative frames"
$tsah resample "$sample" -o "$out/explode-5.tanim" --frames 5

echo; echo "== 3. optimize one BVH for all frames (T-SAH) and compare with the paper's baselines"
$tsah optimize "$sample" -o "$out/explode.tbvh" --seed 1
$tsah info "$out/explode.tbvh"
$tsah evaluate "$sample" --methods sah0,sahstar,tsah0,rebuild --seed 1

echo; echo "== 4. export renderer-ready buffers of frame 0"
$tsah export "$out/explode.tbvh" "$sample" --frame 0 -o "$out/export"

echo; echo "== 5. trace every keyframe with only a refit per frame"
device=cpu
if [[ -x build/release/tests/test_cuda_runtime ]] && command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
  device=cuda
fi
$tsah trace "$sample" "$out/explode.tbvh" --device "$device" --width 640 --height 480 --out "$out/frames"

echo; echo "done: images in $out/frames/, tree in $out/explode.tbvh, buffers in $out/export/"
