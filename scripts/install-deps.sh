#!/usr/bin/env bash
# Installs every Debian 12 package the project builds, tests and runs with; installs only what is
# missing, so running it again is cheap. Works as root or through sudo.
# The CUDA toolkit is not a Debian package: when /usr/local/cuda/bin/nvcc exists the GPU runtime is
# built too, otherwise the CPU path alone is built.
set -euo pipefail

packages=(
  build-essential cmake pkg-config git xz-utils file
  libopenmesh-dev libglm-dev libcli11-dev nlohmann-json3-dev
  libtbb-dev libstb-dev libassimp-dev zlib1g-dev assimp-testmodels
  libgtest-dev googletest
  python3
  python3-dev pybind11-dev python3-pybind11 python3-numpy python3-pytest   # the Python module, its tests
  python3-venv python3-pip python3-setuptools python3-wheel   # pip install . (scripts/test-pip-install.sh)
  libembree-dev gnuplot-nox   # tsah bench: the CPU peer (optional at build time) and its plots
  clang libclang-rt-14-dev    # scripts/fuzz.sh: clang 14 with libFuzzer and the sanitizers
  libopenmpi-dev openmpi-bin  # MPI runs of tsah trace / optimize --segments (optional at build time)
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

if [[ $(id -u) -eq 0 ]]; then sudo=(); else sudo=(sudo); fi
echo "install-deps: installing ${missing[*]}"
"${sudo[@]}" apt-get update -qq
DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
