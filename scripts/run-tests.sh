#!/usr/bin/env bash
# The README's test command: install what is missing, build, run every test.
# usage: scripts/run-tests.sh [PRESET]   (release by default; debug-asan for the sanitizer build)
set -euo pipefail
cd "$(dirname "$0")/.."
preset=${1:-release}
scripts/build.sh "$preset"
ctest --preset "$preset" -j "$(nproc)"
# The Python package as pip installs it (release only: the sanitizer build needs the ASan runtime).
if [[ $preset == release ]]; then
  scripts/test-pip-install.sh "build/$preset/apps/tsah"
fi
