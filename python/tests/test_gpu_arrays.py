"""Runtimes fed from the caller's arrays: refit from vertex positions (checked like an imported
animation), batch dimensions (..., 3) -> (...), out= arrays, on the CPU everywhere and on the GPU
when one is present."""
import numpy as np
import pytest

import tsah

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
    def __init__(self, array):
        self.array = array
        self.__cuda_array_interface__ = {"shape": array.shape, "typestr": array.dtype.str, "strides": None,
                                         "data": (array.ctypes.data, False), "version": 3, "stream": None}


class FakeDlpackDevice:
    """Exposes a DLPack device other than the host's (2: kDLCUDA)."""
    def __dlpack_device__(self):
        return (2, 0)


@pytest.mark.parametrize("kind", RUNTIMES)
def test_device_arrays_are_refused_with_a_clear_error(kind, wave):
    animation, _ = wave
    runtime = make_runtime(kind, wave)
    positions = animation.positions_at(1.0).astype(np.float32)
    o, d = rays(animation, 1.0, (10,))
    cuda = "a CUDA device array \\(__cuda_array_interface__\\); this call takes host arrays \\(numpy\\)"
    with pytest.raises(tsah.ConfigError, match="positions: " + cuda):
        runtime.refit(FakeCudaArray(positions))
    with pytest.raises(tsah.ConfigError, match="origins: " + cuda):
        runtime.trace(FakeCudaArray(o), d)
    with pytest.raises(tsah.ConfigError, match="directions: " + cuda):
        runtime.occluded(o, FakeCudaArray(d))
    with pytest.raises(tsah.ConfigError, match=r"positions: a device array \(DLPack device type 2\); this call takes host"):
        runtime.refit(FakeDlpackDevice())
