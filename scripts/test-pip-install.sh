#!/usr/bin/env bash
# `pip install .` as a Python user does it: into a fresh virtual environment that sees Debian's numpy,
# pybind11 and pytest (--system-site-packages), offline (--no-build-isolation); then `pip wheel .`;
# then the pytest suite against the INSTALLED package (no PYTHONPATH, run from outside the tree).
# usage: scripts/test-pip-install.sh [TSAH_PROGRAM]   (the CLI the tests compare with; default
#        build/release/apps/tsah). TSAH_CUDA (auto|on|off, default off here: the GPU runtime is
#        compiled and tested by the CMake build; this checks the packaging) goes to setup.py.
set -euo pipefail
cd "$(dirname "$0")/.."
source_dir=$PWD
program=$(realpath "${1:-build/release/apps/tsah}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

start=$SECONDS
/usr/bin/python3 -m venv --system-site-packages "$work/venv"
export TSAH_CUDA=${TSAH_CUDA:-off}
"$work/venv/bin/pip" install --quiet --no-build-isolation "$source_dir"
"$work/venv/bin/pip" wheel --quiet --no-build-isolation --no-deps --wheel-dir "$work/wheels" "$source_dir"
wheel=$(ls "$work"/wheels/tsah-*.whl)
for member in tsah/__init__.py tsah/__init__.pyi tsah/py.typed tsah/_build_info.py 'tsah/_tsah\.cpython-[^/]*\.so'; do
  /usr/bin/python3 -c "import re, sys, zipfile; names = zipfile.ZipFile(sys.argv[1]).namelist(); \
sys.exit(0 if any(re.fullmatch(sys.argv[2], n) for n in names) else f'{sys.argv[1]}: no {sys.argv[2]}')" "$wheel" "$member"
done

cd "$work"
env -u PYTHONPATH "$work/venv/bin/python" -c "import sys, tsah; \
sys.exit(0 if tsah.__file__.startswith(sys.prefix) else f'tsah imported from {tsah.__file__}, not the venv')"
env -u PYTHONPATH TSAH_CLI="$program" TSAH_SOURCE_DIR="$source_dir" \
  "$work/venv/bin/python" -m pytest -q -p no:cacheprovider "$source_dir/python/tests"
echo "test-pip-install: pip install, pip wheel and the installed package's tests passed in $((SECONDS - start)) s"
