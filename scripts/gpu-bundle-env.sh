# Sourced by the device-run scripts (gpu-two-level-run.sh, gpu-motion-blur-run.sh) from the
# repository root: makes $out (OUT, default /tmp/tsah-gpu-out), enters the bundle (.gpu), puts its
# libraries on the loader's path, names the device, and unpacks data.tar.xz (a folder `data`) once.
out=${OUT:-/tmp/tsah-gpu-out}
mkdir -p "$out"
cd .gpu || exit 1
export LD_LIBRARY_PATH=$PWD/lib
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
if [ -f data.tar.xz ] && [ ! -d data ]; then
  python3 -c "import tarfile; tarfile.open('data.tar.xz').extractall('.')" || exit 1
fi
