"""Runtimes fed from the caller's arrays: refit from vertex positions (checked like an imported
animation), batch dimensions (..., 3) -> (...), out= arrays, on the CPU everywhere and on the GPU
when one is present; CUDA device arrays (__cuda_array_interface__, DLPack): the protocol checks
everywhere, the GPU runtime's device path against its host path with a device and torch or CuPy."""
import gc
import sys

import numpy as np
import pytest

import tsah
from dlpack_abi import DLManagedTensorVersioned, FakeDlpack, capsule_name, capsule_struct
from device_lib import LIB, needs_device_arrays, new_stream, stream_address, synchronize, to_device, to_host

RUNTIMES = ["cpu", pytest.param("gpu", marks=pytest.mark.skipif(
    not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)"))]


@pytest.fixture(scope="module")
def wave():
    animation = tsah.generate("wave", triangles=600, frames=6, seed=2)
    return animation, tsah.optimize(animation, seed=1, max_leaf=4)


def make_runtime(kind, wave):
    animation, tree = wave
    return tsah.CpuRuntime(tree, animation) if kind == "cpu" else tsah.GpuRuntime(tree, animation)


def rays(animation, time, shape, seed=5):
    rng = np.random.default_rng(seed)
    p = animation.positions_at(time)
    lo, hi = p.min(axis=0), p.max(axis=0)
    targets = lo + rng.random(shape + (3,)) * (hi - lo)
    origins = targets + rng.normal(size=shape + (3,)) * float((hi - lo).max())
    return origins.astype(np.float32), (targets - origins).astype(np.float32)


@pytest.mark.parametrize("kind", RUNTIMES)
def test_refit_from_positions_equals_refit_from_time(kind, wave):
    animation, _ = wave
    by_time, by_positions = make_runtime(kind, wave), make_runtime(kind, wave)
    by_time.refit(2.5)
    by_positions.refit(animation.positions_at(2.5))  # refit takes positions as well as a time
    o, d = rays(animation, 2.5, (500,))
    hits = by_positions.trace(o, d)
    assert (hits["triangle"] >= 0).sum() > 100
    np.testing.assert_array_equal(hits, by_time.trace(o, d))
    by_positions.refit(animation.positions_at(0.0).astype(np.float64))  # converted, then used
    by_time.refit(0.0)
    np.testing.assert_array_equal(by_positions.trace(o, d), by_time.trace(o, d))


@pytest.mark.parametrize("kind", RUNTIMES)
@pytest.mark.parametrize("value, message", [
    (np.nan, "positions: vertex 4 has a NaN or infinite coordinate"),
    (-np.inf, "positions: vertex 4 has a NaN or infinite coordinate"),
    (1e30, r"positions: vertex 4 has coordinate 1e\+30, beyond the supported magnitude 1e\+18"),
])
def test_refit_positions_obey_the_coordinate_limit(kind, wave, value, message):
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    positions = animation.positions_at(1.0).copy()
    positions[4, 1] = value
    for call in (runtime.refit, runtime.refit_positions):
        with pytest.raises(tsah.DataError, match=message):
            call(positions)
    positions[4, 1] = 1e18  # the limit itself is accepted
    runtime.refit(positions)


@pytest.mark.parametrize("kind", RUNTIMES)
def test_refit_argument_errors(kind, wave):
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    v = animation.vertex_count
    with pytest.raises(ValueError, match=rf"positions: expected shape \({v}, 3\), got \({v}, 2\)"):
        runtime.refit(np.zeros((v, 2), np.float32))
    with pytest.raises(TypeError, match="positions: expected a floating-point array, got dtype int32"):
        runtime.refit(np.zeros((v, 3), np.int32))
    with pytest.raises(TypeError, match="positions: expected a numpy array, got str"):
        runtime.refit("1.0")
    with pytest.raises(TypeError, match="positions: expected a numpy array, got float"):
        runtime.refit_positions(1.0)  # the alias takes positions only


@pytest.mark.parametrize("kind", RUNTIMES)
def test_batch_dimensions(kind, wave):
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    o, d = rays(animation, 0.0, (4, 5, 6))
    tmax = np.full((4, 5, 6), 1e9, np.float32)
    tmax[0] = 0.5  # a batch-shaped tmax reaches the right rays
    hits = runtime.trace(o, d, tmax=tmax)
    flat = runtime.trace(o.reshape(-1, 3), d.reshape(-1, 3), tmax=tmax.reshape(-1))
    assert hits.shape == (4, 5, 6) and hits.dtype == flat.dtype
    np.testing.assert_array_equal(hits.reshape(-1), flat)
    assert np.all(hits["triangle"][0] == -1) and np.all(np.isinf(hits["t"][0]))
    blocked = runtime.occluded(o, d, tmax=tmax)
    assert blocked.shape == (4, 5, 6) and blocked.dtype == np.bool_
    np.testing.assert_array_equal(blocked.reshape(-1), runtime.occluded(o.reshape(-1, 3), d.reshape(-1, 3),
                                                                        tmax=tmax.reshape(-1)))
    one = runtime.trace(o[0, 0, 0], d[0, 0, 0])  # a single ray (3,) gives a 0-d result
    assert one.shape == () and one == hits[0, 0, 0]
    with pytest.raises(ValueError, match=r"origins: expected shape \(\.\.\., 3\), got \(4, 5, 6\)"):
        runtime.trace(o[..., 0], d[..., 0])
    with pytest.raises(ValueError, match=r"directions: expected the shape of origins \(4, 5, 6, 3\), got \(20, 6, 3\)"):
        runtime.trace(o, d.reshape(20, 6, 3))
    with pytest.raises(ValueError, match=r"tmin: expected shape \(4, 5, 6\), got \(120,\)"):
        runtime.trace(o, d, tmin=np.zeros(120))


@pytest.mark.parametrize("kind", RUNTIMES)
def test_out_arrays(kind, wave):
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    o, d = rays(animation, 0.0, (8, 25))
    expected = runtime.trace(o, d)
    out = np.empty((8, 25), expected.dtype)
    assert runtime.trace(o, d, out=out) is out
    np.testing.assert_array_equal(out, expected)
    flags = np.empty((8, 25), np.bool_)
    assert runtime.occluded(o, d, out=flags) is flags
    np.testing.assert_array_equal(flags, runtime.occluded(o, d))
    with pytest.raises(ValueError, match=r"out: expected shape \(8, 25\), got \(200,\)"):
        runtime.trace(o, d, out=np.empty(200, expected.dtype))
    with pytest.raises(TypeError, match="out: expected dtype bool, got float32"):
        runtime.occluded(o, d, out=np.empty((8, 25), np.float32))
    with pytest.raises(TypeError, match="out: expected a numpy array, got list"):
        runtime.occluded(o, d, out=[])
    with pytest.raises(ValueError, match="out: must be C-contiguous"):
        runtime.occluded(o, d, out=np.empty((25, 8), np.bool_).T)
    frozen = np.empty((8, 25), np.bool_)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="out: is read-only"):
        runtime.occluded(o, d, out=frozen)


@pytest.mark.parametrize("kind", RUNTIMES)
def test_large_batches_their_first_bad_ray_and_the_batch_time(kind, wave):
    """Batches above 65536 rays are converted on several threads: the same hits as small batches,
    the first bad ray named, and last_ray_pass timing the library's batch alone."""
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    o, d = rays(animation, 0.0, (300000,))
    hits = runtime.trace(o, d)
    assert runtime.last_ray_pass["rays"] == 300000 and runtime.last_ray_pass["ms"] > 0
    np.testing.assert_array_equal(hits[::1000], runtime.trace(o[::1000], d[::1000]))
    np.testing.assert_array_equal(runtime.occluded(o, d)[::1000], runtime.occluded(o[::1000], d[::1000]))
    assert runtime.last_ray_pass["rays"] == 300
    d[200000] = 0.0
    d[290000, 1] = np.nan
    with pytest.raises(tsah.ConfigError, match="rays: ray 200000: direction is zero"):
        runtime.trace(o, d)


def test_cpu_runtime_shares_the_animation(wave):
    """The runtime keeps the caller's Animation alive instead of copying it."""
    import gc
    import weakref
    animation = tsah.generate("wave", triangles=600, frames=6, seed=2)
    runtime = tsah.CpuRuntime(wave[1], animation)
    ref = weakref.ref(animation)
    del animation
    gc.collect()
    assert ref() is not None  # held by the runtime
    runtime.refit(3.0)
    del runtime
    gc.collect()
    assert ref() is None


class FakeCudaArray:
    """Exposes __cuda_array_interface__ over a host buffer: what a CUDA array looks like to the module."""
    def __init__(self, array, **fields):
        self.array = array
        self.__cuda_array_interface__ = {"shape": array.shape, "typestr": array.dtype.str, "strides": None,
                                         "data": (array.ctypes.data, False), "version": 3, "stream": None}
        self.__cuda_array_interface__.update(fields)


class FakeTensor(FakeCudaArray):
    """Like torch and CuPy arrays also a number to Python's C API (float(a) works for one element)."""
    def __float__(self):
        raise TypeError("only one element tensors can be converted to Python scalars")


class FakeDlpackDevice:
    """Exposes a DLPack device other than the host's (2: kDLCUDA)."""
    def __dlpack_device__(self):
        return (2, 0)

    def __dlpack__(self, stream=None):
        raise AssertionError("a CPU runtime must refuse before taking the capsule")


def test_cpu_runtime_refuses_device_arrays_with_a_clear_error(wave):
    animation, _ = wave
    runtime = make_runtime("cpu", wave)
    positions = animation.positions_at(1.0).astype(np.float32)
    o, d = rays(animation, 1.0, (10,))
    cuda = "a CUDA device array \\(__cuda_array_interface__\\); this call takes host arrays \\(numpy\\)"
    with pytest.raises(tsah.ConfigError, match="positions: " + cuda):
        runtime.refit(FakeCudaArray(positions))
    with pytest.raises(tsah.ConfigError, match="positions: " + cuda):
        runtime.refit(FakeTensor(positions))  # positions, not a time
    with pytest.raises(tsah.ConfigError, match="origins: " + cuda):
        runtime.trace(FakeCudaArray(o), d)
    with pytest.raises(tsah.ConfigError, match="directions: " + cuda):
        runtime.occluded(o, FakeCudaArray(d))
    with pytest.raises(tsah.ConfigError, match=r"positions: a device array \(DLPack device type 2\); this call takes host"):
        runtime.refit(FakeDlpackDevice())


# The protocol checks, everywhere (no device touched): tsah._tsah._checked_device_array is the
# function every GpuRuntime argument goes through.
check = tsah._tsah._checked_device_array


def test_cuda_array_interface_is_read_as_the_protocol_says():
    a = np.zeros((5, 3), np.float32)
    got = check(FakeCudaArray(a, stream=7), "positions", ["<f4"])
    assert got == {"data": a.ctypes.data, "shape": (5, 3), "typestr": "<f4", "device": None, "stream": 7}
    # Explicit C-contiguous strides are accepted, as are any strides of an extent-1 dimension.
    assert check(FakeCudaArray(a, strides=(12, 4)), "positions", ["<f4"])["shape"] == (5, 3)
    assert check(FakeCudaArray(a[:1], strides=(999, 4)), "positions", ["<f4"])["shape"] == (1, 3)
    assert check(FakeCudaArray(a, version=2, stream=None), "positions", ["<f4"])["stream"] is None


class CountedInterface:
    """Builds its __cuda_array_interface__ at each access, as torch does (in Python), and counts them;
    raises AttributeError while on the host, as a CPU torch tensor does."""
    def __init__(self, array, on_device=True):
        self.inner, self.on_device, self.reads = FakeCudaArray(array), on_device, 0

    @property
    def __cuda_array_interface__(self):
        self.reads += 1
        if not self.on_device:
            raise AttributeError("Can't get __cuda_array_interface__ on non-CUDA tensor")
        return self.inner.__cuda_array_interface__


def test_cuda_array_interface_is_read_once_per_check():
    a = np.zeros((5, 3), np.float32)
    counted = CountedInterface(a)
    assert check(counted, "positions", ["<f4"])["data"] == a.ctypes.data
    assert counted.reads == 1
    host = CountedInterface(a, on_device=False)
    with pytest.raises(tsah.ArgumentTypeError, match="positions: expected a CUDA device array .* got CountedInterface"):
        check(host, "positions", ["<f4"])
    assert host.reads == 1


@pytest.mark.parametrize("fields, error, message", [
    ({"typestr": "<f8"}, tsah.ArgumentTypeError, "positions: expected a device array of typestr '<f4', got '<f8'"),
    ({"strides": (4, 20)}, tsah.ConfigError, "positions: must be C-contiguous"),
    ({"strides": (24, 4)}, tsah.ConfigError, "positions: must be C-contiguous"),
    ({"shape": (5, -3)}, tsah.ConfigError, "positions: __cuda_array_interface__ has a negative extent"),
    ({"version": 1}, tsah.ConfigError, r"positions: __cuda_array_interface__ version 1 is not supported \(2 or 3\)"),
    ({"stream": 0}, tsah.ConfigError, "positions: __cuda_array_interface__ stream 0 is not allowed"),
    ({"mask": object()}, tsah.ConfigError, "positions: __cuda_array_interface__ has a mask"),
    ({"data": "0x10"}, tsah.ConfigError, "positions: __cuda_array_interface__ has a field of the wrong type"),
    ({"stream": -3}, tsah.ConfigError, "positions: __cuda_array_interface__ stream is not a stream address"),
])
def test_bad_cuda_array_interfaces_get_one_clear_line(fields, error, message):
    with pytest.raises(error, match=message):
        check(FakeCudaArray(np.zeros((5, 3), np.float32), **fields), "positions", ["<f4"])


def test_cuda_array_interface_missing_fields_and_read_only_outputs():
    fake = FakeCudaArray(np.zeros(4, np.bool_))
    del fake.__cuda_array_interface__["data"]
    with pytest.raises(tsah.ConfigError, match="out: __cuda_array_interface__ has no 'data'"):
        check(fake, "out", ["|b1"])
    frozen = FakeCudaArray(np.zeros(4, np.bool_), data=(16, True))
    assert check(frozen, "out", ["|b1"])["data"] == 16  # read-only inputs are fine
    with pytest.raises(tsah.ConfigError, match="out: __cuda_array_interface__ is read-only"):
        check(frozen, "out", ["|b1"], writable=True)
    with pytest.raises(tsah.ArgumentTypeError, match="out: expected a CUDA device array .* got ndarray"):
        check(np.zeros(4, np.bool_), "out", ["|b1"])


def test_stream_arguments():
    fake = FakeDlpack((2, 3))

    class TorchLike:
        cuda_stream = 99

    class CudaCoreLike:
        def __cuda_stream__(self):
            return (0, 77)

    for stream, expected in [(None, 1), (0, 1), (2, 2), (5000, 5000), (TorchLike(), 99), (CudaCoreLike(), 77)]:
        check(fake, "origins", ["<f4"], stream=stream)
        assert fake.streams[-1] == expected
    with pytest.raises(tsah.ArgumentTypeError, match="stream: expected an int .* got str"):
        check(fake, "origins", ["<f4"], stream="default")
    with pytest.raises(tsah.ConfigError, match="stream: must be in 0"):
        check(fake, "origins", ["<f4"], stream=-5)


# With a device and torch or CuPy: device arrays against the host path.
class DlpackOnly:
    """A device array offering DLPack only (torch and CuPy offer both protocols); keeps the keywords of
    each __dlpack__ call and the last capsule."""
    def __init__(self, a):
        self.a, self.asked = a, []

    def __dlpack__(self, **keywords):
        self.asked.append(keywords)
        self.capsule = self.a.__dlpack__(**keywords)
        return self.capsule

    def __dlpack_device__(self):
        return self.a.__dlpack_device__()


PROTOCOLS = ["cuda_array_interface", "dlpack"]


def device_input(a, protocol):
    d = to_device(a)
    return d if protocol == "cuda_array_interface" else DlpackOnly(d)


class CountedDeviceArray:
    """A device array whose __cuda_array_interface__ is built at each access (as torch's) and counted."""
    def __init__(self, a):
        self.a, self.reads = a, 0

    @property
    def __cuda_array_interface__(self):
        self.reads += 1
        return self.a.__cuda_array_interface__


@needs_device_arrays
def test_a_call_reads_each_device_arrays_interface_once(wave):
    animation, tree = wave
    gpu = tsah.GpuRuntime(tree, animation)
    positions = CountedDeviceArray(to_device(animation.positions_at(0.5).astype(np.float32)))
    gpu.refit(positions)  # told apart from a time, checked, read: one access
    assert positions.reads == 1
    o, d = rays(animation, 0.5, (100,))
    o, d = CountedDeviceArray(to_device(o)), CountedDeviceArray(to_device(d))
    gpu.trace(o, d)
    gpu.occluded(o, d)
    assert (o.reads, d.reads) == (2, 2)


class InterfaceOnly:
    """The same device array offering only its __cuda_array_interface__ (the protocol's read)."""
    def __init__(self, a):
        self.__cuda_array_interface__ = a.__cuda_array_interface__


@pytest.mark.skipif(LIB is None or LIB.__name__ != "torch", reason="no CUDA device, or no torch")
def test_plain_torch_tensors_are_read_as_their_interface_says():
    """A plain CUDA tensor is read through its own attributes, not its interface (a Python property):
    the fields must be the interface's, and every other tensor must still take the protocols."""
    torch = LIB
    for dtype, typestr in [(torch.float32, "<f4"), (torch.int32, "<i4"), (torch.uint8, "|u1"), (torch.bool, "|b1")]:
        for shape in [(7, 3), (0, 3), (2, 4, 3)]:
            tensor = torch.zeros(shape, dtype=dtype, device="cuda")
            assert check(tensor, "a", [typestr]) == check(InterfaceOnly(tensor), "a", [typestr])
    plain = torch.zeros((7, 3), device="cuda")
    counted = CountedDeviceArray(plain)
    check(counted, "a", ["<f4"])
    assert counted.reads == 1  # a wrapper is not a plain tensor: its interface is read
    with pytest.raises(tsah.ConfigError, match="a: must be C-contiguous"):
        check(plain.t(), "a", ["<f4"])
    with pytest.raises(tsah.ArgumentTypeError, match="a: expected a device array of typestr '<f4', got '<f8'"):
        check(plain.double(), "a", ["<f4"])

    class Sub(torch.Tensor):
        pass
    assert check(plain.as_subclass(Sub), "a", ["<f4"])["data"] == plain.data_ptr()
    with pytest.raises(tsah.ArgumentTypeError, match="a: expected a CUDA device array"):
        check(plain.cpu(), "a", ["<f4"])


@needs_device_arrays
@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_device_refit_and_trace_equal_the_host_path(wave, protocol):
    animation, _ = wave
    host, device = make_runtime("gpu", wave), make_runtime("gpu", wave)
    positions = animation.positions_at(2.5)
    host.refit(positions)
    device.refit(device_input(positions, protocol))
    o, d = rays(animation, 2.5, (20, 25))
    expected = host.trace(o, d)
    assert (expected["triangle"] >= 0).sum() > 100
    np.testing.assert_array_equal(device.trace(o, d), expected)  # the refit itself
    assert host.last_update["total_ms"] > 0 and host.last_ray_pass["rays"] == 500
    hits = device.trace(device_input(o, protocol), device_input(d, protocol))
    synchronize()
    assert set(hits) == {"t", "u", "v", "triangle"} and hits["t"].shape == (20, 25)
    assert hits["triangle"].typestr == "<i4"
    for field in ("t", "u", "v", "triangle"):
        np.testing.assert_array_equal(to_host(hits[field]), expected[field])
    if protocol == "dlpack":  # DLPack 1.0 asked for first; the library's answer consumed
        positions = device_input(positions, protocol)
        device.refit(positions)
        assert positions.asked[0]["max_version"] == (1, 0)
        assert capsule_name(positions.capsule) == (b"used_dltensor_versioned" if exports_versioned() else b"used_dltensor")
    flags = device.occluded(device_input(o, protocol), device_input(d, protocol))
    synchronize()
    np.testing.assert_array_equal(to_host(flags), host.occluded(o, d))


@needs_device_arrays
def test_device_limits_out_arrays_and_results_as_torch_or_cupy(wave):
    animation, _ = wave
    runtime = make_runtime("gpu", wave)
    o, d = rays(animation, 0.0, (8, 25))
    tmax = np.full((8, 25), 1e9, np.float32)
    tmax[0] = 0.5
    expected = runtime.trace(o, d, tmin=0.01, tmax=tmax)
    out = {"t": to_device(np.zeros((8, 25), np.float32)), "triangle": to_device(np.zeros((8, 25), np.int32))}
    assert runtime.trace(to_device(o), to_device(d), 0.01, to_device(tmax), out=out) is out
    synchronize()
    np.testing.assert_array_equal(to_host(out["t"]), expected["t"])
    np.testing.assert_array_equal(to_host(out["triangle"]), expected["triangle"])
    flags = tsah.DeviceArray((8, 25), "|b1")
    assert runtime.occluded(to_device(o), to_device(d), tmax=1e9, out=flags) is flags
    synchronize()
    np.testing.assert_array_equal(to_host(flags), runtime.occluded(o, d, tmax=1e9))
    hits = runtime.trace(to_device(o), to_device(d))
    synchronize()
    via_interface = LIB.as_tensor(hits["t"], device="cuda") if LIB.__name__ == "torch" else LIB.asarray(hits["t"])
    assert via_interface.data_ptr() == hits["t"].__cuda_array_interface__["data"][0] if LIB.__name__ == "torch" \
        else via_interface.data.ptr == hits["t"].__cuda_array_interface__["data"][0]  # no copy
    np.testing.assert_array_equal(to_host(hits["t"]), runtime.trace(o, d)["t"])


@needs_device_arrays
@pytest.mark.parametrize("wait", [True, False])
def test_device_work_follows_the_callers_stream(wave, wait):
    animation, _ = wave
    runtime = make_runtime("gpu", wave)
    reference = make_runtime("gpu", wave)
    o, d = rays(animation, 4.0, (3000,))
    stream = new_stream()
    positions = to_device(np.full((animation.vertex_count, 3), np.nan, np.float32))
    synchronize()
    with (LIB.cuda.stream(stream) if LIB.__name__ == "torch" else stream):
        # Queued on `stream`: the refit must wait for this copy (before it, the positions are NaN).
        positions.copy_(to_device(animation.positions_at(4.0)), non_blocking=True) if LIB.__name__ == "torch" \
            else positions.set(animation.positions_at(4.0).astype(np.float32), stream=stream)
        # torch's Stream gives its address as cuda_stream; CuPy's as ptr (passed as an int).
        given = stream if LIB.__name__ == "torch" else stream.ptr
        runtime.refit(positions, stream=given, wait=wait)
        hits = runtime.trace(to_device(o), to_device(d), stream=given)
    stream.synchronize()
    runtime.check()
    reference.refit(4.0)
    np.testing.assert_array_equal(to_host(hits["triangle"]), reference.trace(o, d)["triangle"])
    assert hits["t"].__cuda_array_interface__["stream"] == stream_address(stream)


@needs_device_arrays
def test_device_refit_without_waiting_reports_a_refused_frame_later(wave):
    animation, _ = wave
    host, device = make_runtime("gpu", wave), make_runtime("gpu", wave)
    o, d = rays(animation, 2.5, (500,))
    for time in (1.0, 2.5, 4.0):  # good frames, none waited for
        device.refit(to_device(animation.positions_at(time)), wait=False)
        host.refit(animation.positions_at(time))
        synchronize()
        np.testing.assert_array_equal(device.trace(o, d), host.trace(o, d))
    device.check()  # nothing was refused
    expected = host.trace(o, d)  # the frame at 4.0
    bad = animation.positions_at(1.0).copy()
    bad[4, 1] = np.nan
    bad[9, 2] = 1e30
    message = "positions: vertex 4 has a NaN or infinite coordinate"
    device.refit(to_device(bad), wait=False)  # returns: refused on the device
    synchronize()
    np.testing.assert_array_equal(device.trace(o, d), expected)  # the frame is unchanged
    with pytest.raises(tsah.DataError, match=message):
        device.check()
    device.check()  # raised once
    device.refit(to_device(bad), wait=False)
    with pytest.raises(tsah.DataError, match=message):  # the earlier frame's error; these positions are not used
        device.refit(to_device(animation.positions_at(2.0)), wait=False)
    synchronize()
    np.testing.assert_array_equal(device.trace(o, d), expected)
    device.refit(to_device(bad), wait=False)
    with pytest.raises(tsah.DataError, match=message):  # a refit from a time raises it too, and does nothing
        device.refit(2.0)
    np.testing.assert_array_equal(device.trace(o, d), expected)
    device.refit(to_device(animation.positions_at(2.0)), wait=False)  # good again
    host.refit(animation.positions_at(2.0))
    device.check()
    np.testing.assert_array_equal(device.trace(o, d), host.trace(o, d))


@needs_device_arrays
def test_device_argument_errors(wave):
    animation, _ = wave
    runtime = make_runtime("gpu", wave)
    v = animation.vertex_count
    positions = animation.positions_at(1.0).copy()
    o, d = rays(animation, 1.0, (10,))
    with pytest.raises(tsah.ArgumentTypeError, match="positions: expected a device array of typestr '<f4', got '<f8'"):
        runtime.refit(to_device(positions.astype(np.float64)))
    with pytest.raises(tsah.ConfigError, match=rf"positions: expected shape \({v}, 3\), got \({v}, 2\)"):
        runtime.refit(to_device(positions[:, :2]))
    transposed = to_device(np.ascontiguousarray(positions.T)).T
    with pytest.raises(tsah.ConfigError, match="positions: must be C-contiguous"):
        runtime.refit(transposed)
    with pytest.raises(tsah.ConfigError, match="GPU runtime: positions: host memory, not device memory"):
        runtime.refit(FakeCudaArray(positions.astype(np.float32)))
    with pytest.raises(tsah.ConfigError, match="origins: expected shape \\(\\.\\.\\., 3\\), got \\(10,\\)"):
        runtime.trace(to_device(o[:, 0]), to_device(d[:, 0]))
    with pytest.raises(tsah.ArgumentTypeError, match="directions: expected a CUDA device array .* got ndarray"):
        runtime.trace(to_device(o), d)
    with pytest.raises(tsah.ArgumentTypeError, match="tmax: expected a number or a float32 device array like origins"):
        runtime.trace(to_device(o), to_device(d), tmax=np.ones(10, np.float32))
    with pytest.raises(tsah.ConfigError, match="out: unknown field 'w'"):
        runtime.trace(to_device(o), to_device(d), out={"w": to_device(np.zeros(10, np.float32))})
    with pytest.raises(tsah.ConfigError, match=r"out\['t'\]: expected shape \(10,\), got \(9,\)"):
        runtime.trace(to_device(o), to_device(d), out={"t": to_device(np.zeros(9, np.float32))})
    with pytest.raises(tsah.ConfigError, match="GPU runtime: tmin must be finite and >= 0"):
        runtime.occluded(to_device(o), to_device(d), tmin=-1.0)
    for value, message in [(np.nan, "positions: vertex 4 has a NaN or infinite coordinate"),
                           (1e30, r"positions: vertex 4 has coordinate 1e\+30, beyond the supported magnitude")]:
        bad = positions.astype(np.float32)
        bad[4, 1] = value
        with pytest.raises(tsah.DataError, match=message):
            runtime.refit(to_device(bad))
    with pytest.raises(tsah.ConfigError, match="positions: a CUDA device array"):  # the CPU runtime keeps refusing
        make_runtime("cpu", wave).refit(to_device(positions.astype(np.float32)))


def exports_versioned():
    """Whether the library's arrays answer max_version=(1, 0) with a DLPack 1.0 capsule (torch 2.4+,
    CuPy 13+); older ones take no max_version."""
    try:
        return capsule_name(to_device(np.zeros(1, np.float32)).__dlpack__(max_version=(1, 0))) == b"dltensor_versioned"
    except TypeError:
        return False


needs_device = pytest.mark.skipif(not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)")


@needs_device
def test_device_arrays_export_a_versioned_dlpack_capsule_when_asked():
    a = tsah.DeviceArray((4, 3), "<i4")
    refs = sys.getrefcount(a)
    capsule = a.__dlpack__(max_version=(1, 2))
    assert capsule_name(capsule) == b"dltensor_versioned"
    managed = capsule_struct(capsule, DLManagedTensorVersioned)
    assert (managed.version.major, managed.version.minor, managed.flags) == (1, 0, 0)
    t = managed.dl_tensor
    assert (t.data, t.byte_offset) == (a.__cuda_array_interface__["data"][0], 0)
    assert (t.device.device_type, t.device.device_id) == (2, 0)  # kDLCUDA, device 0
    assert (t.ndim, t.shape[0], t.shape[1]) == (2, 4, 3) and not t.strides  # strides NULL: C-contiguous
    assert (t.dtype.code, t.dtype.bits, t.dtype.lanes) == (0, 32, 1)  # kDLInt, 32 bits
    assert sys.getrefcount(a) == refs + 1  # the tensor holds the array
    del managed, t, capsule
    assert sys.getrefcount(a) == refs  # never consumed: the capsule's destructor deleted the tensor
    for max_version in (None, (0, 8)):  # consumers older than DLPack 1.0: the unversioned capsule
        assert capsule_name(a.__dlpack__(max_version=max_version)) == b"dltensor"
    assert sys.getrefcount(a) == refs
    # The module consumes its own versioned capsule.
    exported = DlpackOnly(a)
    assert check(exported, "a", ["<i4"])["shape"] == (4, 3)
    assert exported.asked == [{"stream": 1, "max_version": (1, 0)}]
    assert capsule_name(exported.capsule) == b"used_dltensor_versioned"
    del exported
    assert sys.getrefcount(a) == refs  # the consumer called the deleter
    with pytest.raises(TypeError, match=r"max_version: expected \(major, minor\)"):
        a.__dlpack__(max_version="1.0")
    with pytest.raises(BufferError, match="no copies"):
        a.__dlpack__(max_version=(1, 0), copy=True)


@needs_device_arrays
def test_device_arrays_travel_as_versioned_dlpack_both_ways(wave):
    animation, _ = wave
    runtime = make_runtime("gpu", wave)
    o, d = rays(animation, 0.0, (300,))
    expected = runtime.trace(o, d)["t"]
    origins = DlpackOnly(to_device(o))
    hits = runtime.trace(origins, to_device(d))  # the library's capsule, consumed by trace
    assert origins.asked[0] == {"stream": 1, "max_version": (1, 0)}
    assert capsule_name(origins.capsule) == (b"used_dltensor_versioned" if exports_versioned() else b"used_dltensor")
    # The module's capsule, consumed by the library's from_dlpack: versioned when it asks for DLPack 1.0.
    a = hits["t"]
    exported = DlpackOnly(a)
    refs = sys.getrefcount(a)
    taken = LIB.from_dlpack(exported)
    asked = exported.asked[-1].get("max_version")
    assert capsule_name(exported.capsule) == (b"used_dltensor_versioned" if asked and asked[0] >= 1 else b"used_dltensor")
    address = taken.data_ptr() if LIB.__name__ == "torch" else taken.data.ptr
    assert address == a.__cuda_array_interface__["data"][0]  # no copy
    np.testing.assert_array_equal(to_host(taken), expected)
    assert sys.getrefcount(a) == refs + 1
    del taken
    gc.collect()
    assert sys.getrefcount(a) == refs  # the library called the deleter
