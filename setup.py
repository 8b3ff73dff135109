"""Builds the extension tsah._tsah with this project's CMake (pyproject.toml holds the metadata).

`pip install .` runs CMake on the whole project in Release, builds only the Python module and puts
it into the package. Settings, from the environment:
  TSAH_CUDA=auto|on|off   the GPU runtime: built when nvcc is found (auto, the default), required
                          (on), or left out (off)
  CMAKE_ARGS="..."        more CMake arguments (e.g. -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  CMAKE_BUILD_PARALLEL_LEVEL=N   parallel compile jobs (default: all cores)
"""
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).resolve().parent


def cmake_version():
    text = (ROOT / "CMakeLists.txt").read_text()
    return re.search(r"project\(tsah VERSION ([0-9.]+)", text).group(1)


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        cuda = os.environ.get("TSAH_CUDA", "auto").lower()
        if cuda not in ("auto", "on", "off"):
            raise SystemExit(f"tsah: TSAH_CUDA={cuda!r}: expected auto, on or off")
        build = pathlib.Path(self.build_temp).resolve() / "cmake"
        configure = ["cmake", "-S", str(ROOT), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                     f"-DPython3_EXECUTABLE={sys.executable}", "-DTSAH_BUILD_TESTS=OFF", "-DTSAH_WITH_MPI=OFF",
                     f"-DTSAH_WITH_CUDA={'OFF' if cuda == 'off' else 'ON'}"]
        configure += shlex.split(os.environ.get("CMAKE_ARGS", ""))
        subprocess.run(configure, check=True)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", str(os.cpu_count() or 1))
        subprocess.run(["cmake", "--build", str(build), "--target", "tsah_python", "-j", jobs], check=True)
        if cuda == "on" and not list((build / "cuda_kernels").glob("libtsah_cuda*")):
            raise SystemExit("tsah: TSAH_CUDA=on, but CMake found no CUDA compiler (nvcc): the GPU runtime was not built")

        built = build / "python" / "tsah"
        modules = sorted(built.glob("_tsah*.so"))
        if not modules:
            raise SystemExit(f"tsah: CMake did not build the module (is pybind11-dev installed?): nothing in {built}")
        target = pathlib.Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(modules[0], target)
        # What the module was built with (pybind11's version), read by tsah/__init__.py.
        shutil.copyfile(built / "_build_info.py", target.parent / "_build_info.py")


def numpy_requirement():
    """pybind11 before 2.12 (Debian 12 has 2.10) supports numpy 1.x only: its module must not meet numpy 2."""
    import pybind11
    major_minor = tuple(int(part) for part in pybind11.__version__.split(".")[:2])
    return "numpy>=1.24" if major_minor >= (2, 12) else "numpy>=1.24,<2"


def pyproject_version():
    text = (ROOT / "pyproject.toml").read_text()
    return re.search(r'^version = "([0-9.]+)"', text, re.MULTILINE).group(1)


if pyproject_version() != cmake_version():
    raise SystemExit(f"tsah: pyproject.toml says {pyproject_version()} but CMakeLists.txt says {cmake_version()}")
setup(install_requires=[numpy_requirement()], ext_modules=[CMakeExtension("tsah._tsah")],
      cmdclass={"build_ext": CMakeBuild})
