"""T-SAH: one BVH optimized for every frame of an animation.

The Python layer of the tsah C++ toolkit (docs/python.md). Everything here calls the same C++ code
as the ``tsah`` command line:

>>> import tsah
>>> animation = tsah.load("samples/explode")            # any input `tsah info` reads
>>> tree = tsah.optimize(animation, seed=1)              # as `tsah optimize`
>>> costs = tree.costs(animation, eval_frames=50)        # Eq. 1 per evaluation frame (numpy)
>>> tree.save("explode.tbvh")                            # the same .tbvh as the command line's
>>> trees = tsah.optimize(animation, segments=3)         # a TreeSet, as `tsah optimize --segments 3`
>>> runtime = tsah.CpuRuntime(tree, animation)
>>> runtime.refit(animation.end_time)
>>> hits = runtime.trace(origins, directions)            # numpy (N, 3) arrays -> record array
>>> scene = tsah.build_two_level("scene.json")           # a two-level scene, as `tsah optimize SCENE`
>>> tracer = tsah.TwoLevelRuntime(scene)                 # traced through its instances

Errors carry the command line's one-line messages. All are tsah.Error (a RuntimeError):
tsah.ConfigError (also a ValueError) for a bad option or argument, tsah.DataError (also a
ValueError) for unusable data, its subclass tsah.FileError for an unreadable file, tsah.Failure when
the work itself failed (a write error, no memory, a GPU error). Wrong types and dtypes raise
tsah.ArgumentTypeError, a tsah.ConfigError that is also a TypeError. Ctrl-C stops optimize,
evaluate and load with KeyboardInterrupt.
"""
import sys as _sys

try:
    import numpy as _numpy  # noqa: F401  (every array the module takes or gives is numpy's)
except ImportError as _error:
    raise ImportError(
        f"tsah needs numpy, which this interpreter ({_sys.executable}) cannot import: install it for this "
        "interpreter (Debian: apt install python3-numpy; a virtual environment: pip install numpy)") from _error

# pybind11 before 2.12 reads numpy 1.x's dtype struct directly (itemsize, the strides of new arrays),
# which numpy 2 changed: refuse numpy 2 rather than hand out arrays with wrong strides.
from ._build_info import pybind11_version as _pybind11_version  # noqa: E402


def _major_minor(version):
    return tuple(int(part) for part in version.split(".")[:2] if part.isdigit())


if _major_minor(_numpy.__version__) >= (2,) and _major_minor(_pybind11_version) < (2, 12):
    raise ImportError(
        f"tsah was built with pybind11 {_pybind11_version}, which does not support numpy {_numpy.__version__} "
        f"of this interpreter ({_sys.executable}): use numpy 1.x (pip install 'numpy<2') or rebuild tsah with "
        "pybind11 2.12 or newer")

from ._tsah import (  # noqa: F401  (the public API)
    Animation,
    CpuRuntime,
    ArgumentTypeError,
    ConfigError,
    DataError,
    Error,
    Failure,
    FileError,
    Tree,
    TreeSet,
    TwoLevelRuntime,
    TwoLevelScene,
    __version__,
    cuda_available,
    cuda_built,
    evaluate,
    generate,
    build_two_level,
    load,
    load_two_level,
    optimize,
    read_tree,
    tree_from_bytes,
)

if cuda_built:
    from ._tsah import DeviceArray, GpuRuntime, GpuTwoLevelRuntime  # noqa: F401

__all__ = [
    "Animation", "ArgumentTypeError", "ConfigError", "CpuRuntime", "DataError", "Error", "Failure", "FileError",
    "Tree", "TreeSet", "TwoLevelRuntime", "TwoLevelScene", "__version__", "cuda_available", "cuda_built",
    "build_two_level", "evaluate", "generate", "load", "load_two_level", "optimize", "read_tree", "tree_from_bytes",
] + (["DeviceArray", "GpuRuntime", "GpuTwoLevelRuntime"] if cuda_built else [])
