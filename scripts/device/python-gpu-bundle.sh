#!/usr/bin/env bash
# Packs what scripts/device/python-gpu-check.sh needs on the GPU machine into one ignored folder
# (default .gpu-python), to be carried there with the working tree (whose python/ it builds):
#   prefix/  the gpu-hopper build (sm_90, CUDA) installed with cmake --install;
#   lib/     the shared libraries of Debian packages that the installed tsah links by absolute path
#            (tsahTargets.cmake: Assimp, OpenMeshCore, OpenMeshTools, TBB, stb; rewritten there to
#            these files) and those they load that a bare machine lacks (Assimp's Draco and minizip,
#            the CUDA runtime), each under its soname;
#   bin/     test_cuda_device_arrays.
# usage (repository root, after cmake --preset gpu-hopper):  bash scripts/device/python-gpu-bundle.sh [OUT]
set -euo pipefail
out=${1:-.gpu-python}
build=build/gpu-hopper
cmake --build "$build" -j2 --target tsah tsah_python test_cuda_device_arrays
rm -rf "$out"
mkdir -p "$out/lib" "$out/bin"
cmake --install "$build" --prefix "$out/prefix" > /dev/null
# Neither the command line nor the module built for this machine's Python is used there (the carry
# limit is 64 MiB; the tsah program alone needs Embree and MPI's libraries).
rm -rf "$out/prefix/bin" "$out"/prefix/lib/python3*
cp "$build/tests/test_cuda_device_arrays" "$out/bin/"
# Libraries every Linux machine with the NVIDIA driver provides: never copied (libcudart is: the
# test program needs the one it was built with, and /usr/local/cuda/lib64 may not be on the path).
system='^(linux-vdso|ld-linux|libc\.|libm\.|libdl\.|librt\.|libpthread\.|libstdc\+\+|libgcc_s|libz\.|libcuda\.|libnvidia)'
# A library under its soname, as a plain file (no symbolic links: the folder travels as files).
copy() {
  local name
  name=$(objdump -p "$(readlink -f "$1")" | awk '/SONAME/{print $2}')
  [ -e "$out/lib/$name" ] || cp -L "$1" "$out/lib/$name"
  echo "$name"
}
# The installed targets name Debian's files by absolute path: they name the bundle's instead,
# relative to the install prefix, so the folder works wherever it is unpacked.
targets=$out/prefix/lib/cmake/tsah/tsahTargets.cmake
for file in $(grep -o '/usr/lib/x86_64-linux-gnu/[^;" ]*\.so[.0-9]*' "$targets" | sort -u); do
  name=$(copy "$file")
  sed -i "s#$file#\${_IMPORT_PREFIX}/../lib/$name#g" "$targets"
done
for f in "$out"/bin/* "$out"/lib/*; do
  ldd "$f" | awk '/=> \//{print $1" "$3}' | while read -r name path; do
    [[ $name =~ $system ]] || [ -e "$out/lib/$name" ] || copy "$path" > /dev/null
  done
done
echo "python-gpu-bundle: $(ls "$out/lib" | wc -l) library names, $(du -sh "$out" | cut -f1) in $out"
echo "device run: carry [\"$out\"], command: bash scripts/device/python-gpu-check.sh $out"
