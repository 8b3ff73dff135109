#!/usr/bin/env bash
# One device-machine run of motion blur on the GPU: the CUDA motion-blur and render tests,
# `tsah trace --device cuda --shutter`, and `tsah_gpu_bench --shutter` (blurred and instant frames of
# each scene in one run) with a summary of the blurred/instant ratios. Run from the repository root
# with the bundle in .gpu (as scripts/gpu-device-run.sh; docs/cuda-runtime.md):
#   build:  (without Embree and MPI, whose libraries would not fit the bundle's size limit)
#           cmake --preset gpu-hopper -B build/gpu-mb -DCMAKE_DISABLE_FIND_PACKAGE_embree=ON -DTSAH_WITH_MPI=OFF
#           cmake --build build/gpu-mb -j2 --target tsah tsah_gpu_bench test_cuda_motion_blur
#             test_cuda_motion_blur_render test_cuda_motion_blur_layout   (test_cuda_runtime and test_cuda_cwbvh too when they fit:
#             their CudaRender tests then run as well)
#   data:   tsah resample SCENE -o data/NAME.tanim [--frames 50]; optionally
#           tsah optimize data/NAME.tanim -o data/NAME-tsah.tbvh (else the bench builds SAH0);
#           tar -cJf data.tar.xz data
#   pack:   ../shared/tools/gpu-bundle build/gpu-mb .gpu data.tar.xz   (the carry holds 64 MiB)
#   run:    device tool, carry [".gpu"], command: bash scripts/gpu-motion-blur-run.sh [STEPS]
# STEPS (default "tests trace bench"); SCENES (default: every data/*.tanim), SHUTTER (default 0.5),
# FRAMES (default 50). Results go to $OUT: tests.log, trace-NAME.json, blur-NAME.json.
set -u
steps=${1:-tests trace bench}
shutter=${SHUTTER:-0.5}
frames=${FRAMES:-50}
. "$(dirname "$0")/gpu-bundle-env.sh"
scenes=${SCENES:-$(for f in data/*.tanim; do basename "$f" .tanim; done)}
has() { [[ " $steps " == *" $1 "* ]]; }
tree() { [ -f "data/$1-tsah.tbvh" ] && echo "--tree tsah=data/$1-tsah.tbvh"; }

if has tests; then
  : > "$out/tests.log"
  for t in "test_cuda_motion_blur_render" "test_cuda_motion_blur" "test_cuda_motion_blur_layout" "test_cuda_runtime --gtest_filter=CudaRender.*" \
           "test_cuda_cwbvh --gtest_filter=CudaRender.*"; do
    [ -x "./bin/${t%% *}" ] || continue  # not in this bundle
    timeout 300 ./bin/$t >> "$out/tests.log" 2>&1
    echo "$t: rc=$?"
  done
  grep -E "^\[  (PASSED|FAILED|SKIPPED) |Failure|Expected|Which is|Value of" "$out/tests.log" | head -40
fi

if has trace; then
  for s in $scenes; do
    [ -f "data/$s-tsah.tbvh" ] || continue  # tsah trace needs a tree file
    timeout 300 ./bin/tsah trace "data/$s.tanim" "data/$s-tsah.tbvh" --device cuda --frames 10 --no-images \
      --shutter "$shutter" --json > "$out/trace-$s.json"
    echo "trace $s: rc=$? keys per frame: $(grep -o '"keys":[0-9]*' "$out/trace-$s.json" | cut -d: -f2 | tr '\n' ' ')"
  done
fi

if has bench; then
  for s in $scenes; do
    # shellcheck disable=SC2046
    timeout 500 ./bin/tsah_gpu_bench --input "data/$s.tanim" $(tree "$s") --rebuild none --layout bvh2 \
      --frames "$frames" --shutter "$shutter" > "$out/blur-$s.json"
    echo "bench $s: rc=$?"
  done
  python3 - "$out" $scenes <<'EOF'
import json, sys
out, scenes = sys.argv[1], sys.argv[2:]
print(f"{'scene':14} {'tree':6} {'keys':>5} {'instant ms':>10} {'blurred ms':>10} {'total x':>8} {'update x':>8} "
      f"{'trace x':>8} {'bytes x':>8}")
for s in scenes:
    try:
        data = json.load(open(f"{out}/blur-{s}.json"))
    except (OSError, ValueError) as e:
        print(f"{s:14} no result ({e})")
        continue
    for m in data["methods"]:
        b, r = m["blurred"], m["blurred_over_instant"]
        print(f"{s:14} {m['name']:6} {b['keys']['mean']:5.2f} {m['total_ms']['mean']:10.3f} {b['total_ms']['mean']:10.3f} "
              f"{r['total']:8.2f} {r['update']:8.2f} {r.get('trace', 0):8.2f} {b['bytes']['blurred_over_instant']:8.2f}")
EOF
fi
