"""The device library of the GPU-array tests: torch or CuPy when a CUDA device is present (LIB, or
None), and the few calls the tests make through it."""
import numpy as np
import pytest

import tsah


def device_library():
    if not tsah.cuda_available():
        return None
    for name in ("torch", "cupy"):
        try:
            return __import__(name)
        except ImportError:
            continue
    return None


LIB = device_library()
needs_device_arrays = pytest.mark.skipif(LIB is None, reason="no CUDA device, or neither torch nor CuPy")


def to_device(a):
    return LIB.from_numpy(np.ascontiguousarray(a)).cuda() if LIB.__name__ == "torch" else LIB.asarray(a)


def to_host(a):
    if isinstance(a, tsah.DeviceArray):
        a = LIB.from_dlpack(a) if LIB.__name__ == "torch" else LIB.asarray(a)
    return a.cpu().numpy() if LIB.__name__ == "torch" else LIB.asnumpy(a)


def synchronize():
    (LIB.cuda.synchronize if LIB.__name__ == "torch" else LIB.cuda.Device().synchronize)()


def new_stream():
    return LIB.cuda.Stream() if LIB.__name__ == "torch" else LIB.cuda.Stream(non_blocking=True)


def stream_address(stream):
    return stream.cuda_stream if LIB.__name__ == "torch" else stream.ptr
