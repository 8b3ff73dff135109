#!/usr/bin/env bash
# On the GPU machine (Python 3.12 with numpy, pybind11, torch and/or CuPy, g++, CMake, nvcc; none of
# the Debian packages tsah uses): builds python/ standalone against the bundled install, then runs
# the C++ device-array test, the pytest files of the GPU arrays (and DLPack) and their benchmark.
#   bundle:  bash scripts/device/python-gpu-bundle.sh .gpu-python      (on the build machine)
#   run:     bash scripts/device/python-gpu-check.sh [BUNDLE=.gpu-python] [STEPS]   (repository root)
# STEPS (default "build test pytest bench"). Logs and bench JSON go to $OUT (default /tmp/tsah-py-out):
# build.log, test_cuda_device_arrays.log, pytest.log, gpu-arrays.json. BENCH_ARGS passes options to
# python/bench/gpu_arrays.py (e.g. "--animation ../shared/data/S.tanim").
set -u
bundle=$(cd "${1:-.gpu-python}" && pwd) || exit 1
steps=${2:-build test pytest bench}
out=${OUT:-/tmp/tsah-py-out}
mkdir -p "$out"
python=${PYTHON:-$(command -v python3)}
module=$bundle/build-python
has() { [[ " $steps " == *" $1 "* ]]; }
export LD_LIBRARY_PATH=$bundle/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
status=0

if has build; then
  start=$SECONDS
  { cmake -S python -B "$module" -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$bundle/prefix" \
      -Dpybind11_DIR="$("$python" -m pybind11 --cmakedir)" -DPython3_EXECUTABLE="$python" &&
    cmake --build "$module" -j"$(nproc)"; } > "$out/build.log" 2>&1
  rc=$?; status=$((status | rc))
  echo "build: rc=$rc in $((SECONDS - start)) s"; [ $rc -eq 0 ] || tail -20 "$out/build.log"
fi

if has test; then
  start=$SECONDS
  timeout 300 "$bundle/bin/test_cuda_device_arrays" > "$out/test_cuda_device_arrays.log" 2>&1
  rc=$?; status=$((status | rc))
  echo "test_cuda_device_arrays: rc=$rc in $((SECONDS - start)) s"
  grep -E "^\[  (PASSED|FAILED|SKIPPED) |^device refit|tests ran|Failure|Expected|Which is" "$out/test_cuda_device_arrays.log" | head -30
fi

if has pytest; then
  start=$SECONDS
  PYTHONPATH=$module timeout 400 "$python" -m pytest -q -rs -p no:cacheprovider python/tests/test_gpu_arrays.py \
    python/tests/test_dlpack.py python/tests/test_stubs.py python/tests/test_construction.py python/tests/test_two_level.py python/tests/test_cpu_batch.py python/tests/test_runtime.py > "$out/pytest.log" 2>&1
  rc=$?; status=$((status | rc))
  echo "pytest: rc=$rc in $((SECONDS - start)) s"; tail -15 "$out/pytest.log"
fi

if has bench; then
  start=$SECONDS
  # shellcheck disable=SC2086  # BENCH_ARGS is a list of options
  PYTHONPATH=$module timeout 500 "$python" python/bench/gpu_arrays.py ${BENCH_ARGS:-} > "$out/gpu-arrays.json" 2> "$out/bench.log"
  rc=$?; status=$((status | rc))
  echo "bench: rc=$rc in $((SECONDS - start)) s"; cat "$out/gpu-arrays.json"; [ $rc -eq 0 ] || tail -5 "$out/bench.log"
fi
exit $status
