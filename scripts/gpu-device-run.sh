#!/usr/bin/env bash
# One device-machine run: GPU tests, compute-sanitizer (memcheck) on one short trace, and the
# benchmarks. Run from the repository root with the bundle in .gpu (see docs/cuda-runtime.md):
#   build:  cmake -B build/cuda -DCMAKE_CUDA_ARCHITECTURES=90 -DCMAKE_BUILD_TYPE=Release
#           make -C build/cuda tsah test_cuda_runtime tsah_gpu_bench
#   pack:   ../shared/tools/gpu-bundle build/cuda .gpu data.tar.xz
#           (data.tar.xz: SCENE.tanim and SCENE-{sah0,sahstar,tsah}.tbvh made with tsah resample /
#           tsah optimize)
#   run:    device tool, carry [".gpu"], command: bash scripts/gpu-device-run.sh [STEPS]
# STEPS (default "tests memcheck scenes scaling") picks what runs; "nographs" adds runs without CUDA
# graphs. Results go to $OUT (at most 8 files come back): tests.log, memcheck.log, bench-*.json, and
# with IMAGES=1 cpu.png and gpu.png of the CPU/GPU comparison.
set -u
steps=${1:-tests memcheck scenes scaling}
scenes=${SCENES:-horse-gallop horse-collapse samba}
out=${OUT:-/tmp/tsah-gpu-out}
mkdir -p "$out"
cd .gpu || exit 1
export LD_LIBRARY_PATH=$PWD/lib
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.max.sm --format=csv,noheader
if [ -f data.tar.xz ] && [ ! -d data ]; then
  python3 -c "import tarfile; tarfile.open('data.tar.xz').extractall('data')" || exit 1
fi
has() { [[ " $steps " == *" $1 "* ]]; }

if has tests; then
  start=$SECONDS
  timeout 400 ./bin/test_cuda_runtime > "$out/tests.log" 2>&1
  echo "tests: rc=$? in $((SECONDS - start)) s"
  grep -E "^\[  (PASSED|FAILED|SKIPPED) |tests ran|Failure|error|Expected|Which is|Value of" "$out/tests.log" | head -40
fi

if has memcheck; then
  cs=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
  if [ -x "$cs" ]; then
    # memcheck on one short trace of every path (refit, both traversals, both rebuilds), then
    # racecheck (shared memory) on the rebuilds alone.
    start=$SECONDS
    timeout 300 "$cs" --tool memcheck --error-exitcode 3 --log-file "$out/memcheck.log" ./bin/tsah_gpu_bench \
      --input data/horse-gallop.tanim --tree tsah=data/horse-gallop-tsah.tbvh --frames 2 --width 256 --height 192 \
      --traversal both > /dev/null
    echo "memcheck: rc=$? in $((SECONDS - start)) s: $(grep -E 'ERROR SUMMARY' "$out/memcheck.log")"
    start=$SECONDS
    timeout 300 "$cs" --tool racecheck --error-exitcode 3 --log-file "$out/racecheck.log" ./bin/tsah_gpu_bench \
      --input data/horse-gallop.tanim --tree tsah=data/horse-gallop-tsah.tbvh --frames 1 --no-render > /dev/null
    echo "racecheck: rc=$? in $((SECONDS - start)) s: $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$out/racecheck.log")"
    cat "$out/racecheck.log" >> "$out/memcheck.log"; rm -f "$out/racecheck.log"
  else
    echo "memcheck: compute-sanitizer not found" | tee "$out/memcheck.log"
  fi
fi

if has scenes; then
  for s in $scenes; do
    [ -f "data/$s.tanim" ] || continue
    trees=""
    for m in sah0 sahstar tsah; do [ -f "data/$s-$m.tbvh" ] && trees="$trees --tree $m=data/$s-$m.tbvh"; done
    extra=""
    [ "$s" = horse-gallop ] && extra="--cpu-compare --traversal both ${IMAGES:+--image-dir $out}"
    start=$SECONDS
    timeout 300 ./bin/tsah_gpu_bench --input "data/$s.tanim" $trees --frames 50 $extra > "$out/bench-$s.json" 2> "$out/bench-$s.err"
    echo "bench $s: rc=$? in $((SECONDS - start)) s"; cat "$out/bench-$s.err"; rm -f "$out/bench-$s.err"
  done
fi

if has scaling; then
  start=$SECONDS
  timeout 300 ./bin/tsah_gpu_bench --generate wave:1000000:4 --frames 4 > "$out/bench-wave1m.json" 2> "$out/wave.err"
  echo "bench wave 1M: rc=$? in $((SECONDS - start)) s"; cat "$out/wave.err"; rm -f "$out/wave.err"
fi

if has nographs; then  # the same without CUDA graphs: what the launches cost
  start=$SECONDS
  timeout 300 ./bin/tsah_gpu_bench --input data/horse-gallop.tanim --tree tsah=data/horse-gallop-tsah.tbvh --frames 50 \
    --no-graphs > "$out/bench-nographs-horse-gallop.json"
  timeout 300 ./bin/tsah_gpu_bench --generate wave:1000000:4 --frames 4 --no-graphs > "$out/bench-nographs-wave1m.json"
  echo "no graphs: rc=$? in $((SECONDS - start)) s"
fi

# A short table for the reply's tail.
python3 - "$out" <<'PY'
import json, glob, sys, os
for f in sorted(glob.glob(os.path.join(sys.argv[1], "bench-*.json"))):
    try:
        d = json.load(open(f))
    except Exception as e:
        print(os.path.basename(f), "unreadable:", e); continue
    print(os.path.basename(f), d["device"]["name"], d["input"]["triangles"], "triangles, graphs", d["settings"].get("graphs"))
    for m in d["methods"]:
        tr = m.get("trace", {})
        upd = m["update_ms"]["mean"]
        row = f'  {m["name"]:>10} {m["traversal"]:>10} update {upd:7.3f} ms'
        if m["kind"] == "rebuild":
            row += f' bare {m["bare_build_ms"]["mean"]:.3f} full {m["build_collapse_woop_ms"]["mean"]:.3f}'
        else:
            row += f' per Mtri {m["update_ms_per_million_triangles"]["mean"]:.3f}'
        if tr:
            row += f' | prim {tr["primary"]["mrays_per_s"]:7.0f} ao {tr["ao"]["mrays_per_s"]:7.0f} shadow {tr["shadow"]["mrays_per_s"]:7.0f} MRays/s'
        row += f' | total {m["total_ms"]["mean"]:.3f} ms'
        print(row)
    if "cpu_compare" in d: print("  cpu_compare", d["cpu_compare"])
PY
