#!/usr/bin/env bash
# compute-sanitizer over every GPU code path, for the device machine: memcheck (with leak check),
# racecheck, initcheck and synccheck over every CUDA test program, and over `tsah trace --device
# cuda` (refit, both GPU rebuilds, a tree set) and tsah_gpu_bench (both traversals of both layouts,
# rebuilds, rendering) on a small generated sample. Writes one summary, $OUT/gpu-sanitize.md, plus one log per
# run; exit status 1 when any run reports an error or fails.
#
# Prepare on the build machine (docs/fuzzing.md, "GPU sanitizers"):
#   cmake -S . -B build/cuda -DCMAKE_CUDA_ARCHITECTURES=90 -DCMAKE_BUILD_TYPE=RelWithDebInfo
#   cmake --build build/cuda -j2 --target tsah tsah_gpu_bench test_cuda_runtime test_cuda_tree_set \
#     test_cuda_optimizer test_cuda_cwbvh test_cuda_cwbvh_rebuild test_cuda_cwbvh_convert
#   ../shared/tools/gpu-bundle build/cuda .gpu
# Run (device tool, carry [".gpu"]):  bash scripts/gpu-sanitize.sh [TOOLS]   (default: all four)
set -u
tools=${1:-memcheck racecheck initcheck synccheck}
out=${OUT:-/tmp/tsah-gpu-sanitize}
mkdir -p "$out"
cd .gpu || { echo "gpu-sanitize: no .gpu bundle (see the header of this script)" >&2; exit 1; }
export LD_LIBRARY_PATH=$PWD/lib
cs=$(command -v compute-sanitizer || true)
for c in /usr/local/cuda/bin/compute-sanitizer /usr/local/cuda/compute-sanitizer/compute-sanitizer; do
  [ -z "$cs" ] && [ -x "$c" ] && cs=$c
done
[ -n "$cs" ] || { echo "gpu-sanitize: compute-sanitizer not found" >&2; exit 1; }
summary=$out/gpu-sanitize.md
{
  echo "# compute-sanitizer, $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo
  echo "GPU: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null | head -1); $("$cs" --version | tail -1)"
  echo
  echo "| tool | run | exit | sanitizer summary |"
  echo "|---|---|--:|---|"
} >"$summary"

# The sample: a generated explosion, a tree and a tree set for it (made on the device: no data to carry).
work=$(mktemp -d)
./bin/tsah generate explode -o "$work/s.tanim" --triangles 3000 --frames 6 --seed 5 >/dev/null &&
  ./bin/tsah optimize "$work/s.tanim" -o "$work/s.tbvh" --frames 3 >/dev/null &&
  ./bin/tsah optimize "$work/s.tanim" -o "$work/set.tbvh" --segments 2 --frames 3 >/dev/null ||
  { echo "gpu-sanitize: could not make the sample" | tee -a "$summary"; exit 1; }

trace=(./bin/tsah trace "$work/s.tanim" "$work/s.tbvh" --device cuda --frames 2 --width 96 --height 64 --ao 2 --shadow 1 --no-images)
declare -A runs=(
  [trace-refit]="${trace[*]}"
  [trace-lbvh]="${trace[*]} --rebuild lbvh"
  [trace-hlbvh-sah]="${trace[*]} --rebuild hlbvh-sah"
  [trace-lbvh-cwbvh]="${trace[*]} --rebuild lbvh --layout cwbvh"
  [trace-hlbvh-sah-cwbvh]="${trace[*]} --rebuild hlbvh-sah --layout cwbvh"
  [trace-tree-set]="./bin/tsah trace $work/s.tanim $work/set.tbvh --device cuda --frames 3 --width 96 --height 64 --ao 2 --shadow 1 --no-images"
  [gpu-bench]="./bin/tsah_gpu_bench --input $work/s.tanim --tree tsah=$work/s.tbvh --frames 2 --width 128 --height 96 --traversal both --rebuild lbvh,hlbvh-sah"
  [gpu-bench-cwbvh-passes]="./bin/tsah_gpu_bench --input $work/s.tanim --tree tsah=$work/s.tbvh --frames 2 --width 128 --height 96 --traversal both --layout cwbvh --no-fuse --rebuild none"
)
# Test programs that know it run their short cases (test_cuda_optimizer: small inputs, few rounds).
export TSAH_CUDA_TESTS=short
for t in ./bin/test_cuda_*; do
  [ -x "$t" ] && runs[$(basename "$t")]="$t"
done

status=0
for tool in $tools; do
  extra=()
  [ "$tool" = memcheck ] && extra=(--leak-check full)
  for name in $(printf '%s\n' "${!runs[@]}" | sort); do
    log=$out/$tool-$name.log
    # shellcheck disable=SC2086  # the command lines above are word lists
    timeout 900 "$cs" --tool "$tool" "${extra[@]}" --error-exitcode 3 --log-file "$log" ${runs[$name]} >"$out/$tool-$name.out" 2>&1
    rc=$?
    result=$(grep -hE 'ERROR SUMMARY|RACECHECK SUMMARY|LEAK SUMMARY' "$log" | tr '\n' ' ')
    [ "$rc" = 0 ] || status=1
    # Test programs: how many tests passed, failed or skipped (on a GPU machine a skipped test checks
    # nothing, so it fails the run).
    if [[ $name == test_* ]]; then
      counts=$(grep -hE '^\[ +(PASSED|SKIPPED|FAILED) +\] [0-9]+ tests?' "$out/$tool-$name.out" | sed 's/[][]//g; s/  */ /g' | tr '\n' ';')
      result="$result; $counts"
      grep -qE '^\[ +SKIPPED +\] [0-9]+ test' "$out/$tool-$name.out" && status=1
    fi
    [ "$rc" = 0 ] || result="$result; $(grep -m1 -v '^=' "$out/$tool-$name.out" | cut -c1-160)"
    echo "| $tool | $name | $rc | ${result:-no summary (see $tool-$name.log)} |" >>"$summary"
  done
done
rm -rf "$work"
cat "$summary"
exit $status
