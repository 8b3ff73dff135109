#!/usr/bin/env bash
# One device-machine run of the two-level renderer on the GPU: the GPU render tests (the two-level
# renderer against the CPU renderer; the flat renderer's tests, whose fused passes it shares; the
# two-level runtime's, whose trace it shares), then `tsah trace` of demo.json's two-level tree on the
# CPU (bvh2) and on the GPU, compared frame by frame. Run from the repository root with the bundle
# in .gpu (as scripts/gpu-two-level-run.sh; docs/cuda-runtime.md):
#   build:  cmake --preset gpu-hopper -B build/gpu-tlr -DCMAKE_DISABLE_FIND_PACKAGE_embree=ON -DTSAH_WITH_MPI=OFF
#           cmake --build build/gpu-tlr -j2 --target tsah test_cuda_two_level_render test_cuda_two_level \
#             test_cuda_runtime test_cuda_motion_blur_render
#   pack:   ../shared/tools/gpu-bundle build/gpu-tlr .gpu samples
#   run:    device tool, carry [".gpu"], command: bash scripts/gpu-two-level-render-run.sh [STEPS]
# STEPS (default "tests trace"). Results go to $OUT: tests-NAME.log, trace-cpu.json, trace-gpu.json,
# cpu-frame_0010.png and gpu-frame_0010.png. Success: every test program PASSED (none FAILED), and
# the trace step's line "trace: 21 frames, ray counts within 0.2% + 8: 21".
set -u
steps=${1:-tests trace}
. "$(dirname "$0")/gpu-bundle-env.sh"
has() { [[ " $steps " == *" $1 "* ]]; }

if has tests; then
  for t in test_cuda_two_level_render test_cuda_two_level test_cuda_runtime test_cuda_motion_blur_render; do
    timeout 300 "./bin/$t" > "$out/tests-$t.log" 2>&1
    echo "$t: rc=$?"
    grep -E "^\[  (PASSED|FAILED|SKIPPED) |Failure|Expected|Which is|Value of" "$out/tests-$t.log" | head -20
  done
fi

if has trace; then
  scene=samples/scenes/demo.json
  view=(--frames 21 --width 320 --height 240 --json)
  ./bin/tsah optimize "$scene" -o demo.tbvh --structure two-level --frames 3 > /dev/null || exit 1
  timeout 200 ./bin/tsah trace "$scene" demo.tbvh "${view[@]}" --layout bvh2 --out cpu > "$out/trace-cpu.json"
  echo "trace cpu: rc=$?"
  timeout 200 ./bin/tsah trace "$scene" demo.tbvh "${view[@]}" --device cuda --out gpu > "$out/trace-gpu.json"
  echo "trace gpu: rc=$?"
  cp cpu/frame_0010.png "$out/cpu-frame_0010.png"
  cp gpu/frame_0010.png "$out/gpu-frame_0010.png"
  python3 - "$out/trace-cpu.json" "$out/trace-gpu.json" <<'EOF'
import filecmp, json, sys
cpu, gpu = (json.load(open(p)) for p in sys.argv[1:3])
close = same = 0
for a, b in zip(cpu["frames"], gpu["frames"]):
    ra, rb = a["rays"], b["rays"]
    ok = ra["primary"] == rb["primary"] and all(abs(ra[k] - rb[k]) <= 0.002 * ra[k] + 8 for k in ("ao", "shadow"))
    close += ok
    same += filecmp.cmp(a["image"], b["image"], shallow=False)
    if not ok:
        print("frame", a["frame"], "rays cpu", ra, "gpu", rb)
print(f"trace: {len(gpu['frames'])} frames, ray counts within 0.2% + 8: {close}, byte-identical PNGs: {same}")
print("gpu:", gpu["device"], gpu["timer"], "two_level:", gpu["two_level"]["tlas_update"],
      "average update_ms", round(gpu["average"]["update_ms"], 3), "frame_ms", round(gpu["average"]["frame_ms"], 3))
EOF
fi
