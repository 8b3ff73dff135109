#!/usr/bin/env bash
# One device-machine run of the GPU two-level runtime: test_cuda_two_level and
# test_cuda_two_level_motion, then
# tsah_two_level_gpu_bench over the bench scenes (samples/scenes/bench). Run from the repository
# root with the bundle in .gpu (as scripts/gpu-device-run.sh; docs/cuda-runtime.md):
#   build:  cmake --preset gpu-hopper -B build/gpu-tl -DCMAKE_DISABLE_FIND_PACKAGE_embree=ON -DTSAH_WITH_MPI=OFF
#           cmake --build build/gpu-tl -j2 --target test_cuda_two_level test_cuda_two_level_motion \
#             tsah_two_level_gpu_bench
#   data:   the scenes' objects under a folder `data` laid out as ../shared/data (md2/faerie.md2,
#           md2/sydney.md2, static/sibenik.obj.xz, static/armadillo.off.xz, static/bunny00.off.xz,
#           static/refined_elephant.off.xz, sequences/horse-gallop.tar.xz: about 7.5 MB) and the
#           scene files: mkdir -p data/static data/md2 data/sequences && cp those files there &&
#           cp samples/scenes/bench/{crowd,town,horses8m}.json data/ && tar -cJf data.tar.xz data
#   pack:   ../shared/tools/gpu-bundle build/gpu-tl .gpu data.tar.xz
#   run:    device tool, carry [".gpu"], command: bash scripts/gpu-two-level-run.sh [STEPS]
# STEPS (default "tests bench"); SCENES (default "crowd town horses8m"), FRAMES (default 50).
# The bench builds each structure on the machine's CPU (saved as data/NAME.tbvh, reused by a later
# step of the same run). Results go to $OUT: tests.log, two-level-NAME.json.
set -u
steps=${1:-tests bench}
frames=${FRAMES:-50}
. "$(dirname "$0")/gpu-bundle-env.sh"
export TSAH_DATA_DIR=$PWD/data
has() { [[ " $steps " == *" $1 "* ]]; }

if has tests; then
  : > "$out/tests.log"
  for t in test_cuda_two_level test_cuda_two_level_motion; do
    [ -x "./bin/$t" ] || continue  # not in this bundle
    timeout 300 ./bin/$t >> "$out/tests.log" 2>&1
    echo "$t: rc=$?"
  done
  grep -E "^\[  (PASSED|FAILED|SKIPPED) |Failure|Expected|Which is|Value of" "$out/tests.log" | head -40
fi

if has bench; then
  for s in ${SCENES:-crowd town horses8m}; do
    if [ -f "data/$s.tbvh" ]; then tree=(--tree "data/$s.tbvh"); else tree=(--save-tree "data/$s.tbvh"); fi
    timeout 550 ./bin/tsah_two_level_gpu_bench "data/$s.json" "${tree[@]}" --frames "$frames" > "$out/two-level-$s.json"
    echo "bench $s: rc=$? median: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['median'])" \
      "$out/two-level-$s.json" 2>/dev/null)"
  done
fi
