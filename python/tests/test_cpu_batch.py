"""CpuRuntime.trace / occluded (rays made, checked and traced from the numpy arrays in one task per
chunk, hits written straight into the result) against the C++ batch on Ray structs made beforehand
(CpuRuntime._ray_struct_batch): the same bits in every layout, for ray counts that leave the last
chunk short, batch dimensions, per-ray limits and out=; and the benchmark script's JSON."""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import tsah

BENCH = pathlib.Path(__file__).resolve().parents[1] / "bench" / "cpu_batch.py"


@pytest.fixture(scope="module")
def wave():
    animation = tsah.generate("wave", triangles=2000, frames=4, seed=5)
    return animation, tsah.optimize(animation, method="sah0")


def runtime_or_skip(wave, layout, threads=0):
    animation, tree = wave
    try:
        runtime = tsah.CpuRuntime(tree, animation, threads=threads, layout=layout)
    except tsah.ConfigError as e:  # bvh8 needs AVX2: a processor without it refuses that layout
        assert layout == "bvh8" and "AVX2" in str(e)
        pytest.skip(str(e))
    runtime.refit(1.5)
    return runtime


def rays(animation, shape, seed):
    """Rays of batch shape `shape` from around the frame's box toward points inside it (hits and
    misses), with per-ray limits that differ between neighbours."""
    rng = np.random.default_rng(seed)
    p = animation.positions_at(1.5)
    lo, hi = p.min(axis=0), p.max(axis=0)
    targets = lo + rng.random(shape + (3,)) * (hi - lo)
    origins = targets + rng.normal(size=shape + (3,)) * float((hi - lo).max())
    count = int(np.prod(shape))
    tmin = np.where(np.arange(count) % 5 == 0, 0.3, 0.0).reshape(shape).astype(np.float32)
    tmax = np.where(np.arange(count) % 3 == 0, 0.8, np.inf).reshape(shape).astype(np.float32)
    return origins.astype(np.float32), (targets - origins).astype(np.float32), tmin, tmax


# Counts around the runtime's chunk of 1024 rays and past the conversion threads' 65536.
@pytest.mark.parametrize("layout", ["bvh2", "bvh4", "bvh8"])
@pytest.mark.parametrize("shape", [(1,), (1023,), (3 * 1024 + 5,), (5, 619), (70001,)])
def test_trace_equals_the_ray_struct_batch(wave, layout, shape):
    runtime = runtime_or_skip(wave, layout, threads=3)
    o, d, tmin, tmax = rays(wave[0], shape, seed=sum(shape))
    for lo, hi in ((tmin, tmax), (0.0, np.inf), (0.2, 1e30)):
        want, _ = runtime._ray_struct_batch(o, d, lo, hi)
        got = runtime.trace(o, d, lo, hi)
        assert got.shape == shape and want.shape == shape
        assert got.tobytes() == want.tobytes()  # every field, bit for bit
        misses = got["triangle"] < 0
        assert np.all(np.isinf(got["t"][misses])) and np.all(got["u"][misses] == 0)
        want_any, _ = runtime._ray_struct_batch(o, d, lo, hi, occluded=True)
        got_any = runtime.occluded(o, d, lo, hi)
        assert got_any.dtype == np.bool_ and got_any.shape == shape
        np.testing.assert_array_equal(got_any, want_any)
    if shape[0] > 100:  # a meaningful batch: hits and misses
        assert 0 < (want["triangle"] >= 0).sum() < want.size


@pytest.mark.parametrize("layout", ["bvh2", "bvh8"])
def test_out_is_filled_in_place(wave, layout):
    runtime = runtime_or_skip(wave, layout)
    o, d, tmin, tmax = rays(wave[0], (7, 1031), seed=9)
    want, _ = runtime._ray_struct_batch(o, d, tmin, tmax)
    out = np.full((7, 1031), -1, want.dtype)  # stale values everywhere: every record must be written
    assert runtime.trace(o, d, tmin, tmax, out=out) is out
    assert out.tobytes() == want.tobytes()
    flags = np.ones((7, 1031), bool)
    want_any, _ = runtime._ray_struct_batch(o, d, tmin, tmax, occluded=True)
    assert runtime.occluded(o, d, tmin, tmax, out=flags) is flags
    np.testing.assert_array_equal(flags, want_any)


def test_float64_and_strided_rays_trace_as_float32(wave):
    runtime = runtime_or_skip(wave, "bvh4")
    o, d, tmin, tmax = rays(wave[0], (2000,), seed=4)
    want = runtime.trace(o, d, tmin, tmax)
    wide = np.empty((2000, 6), np.float32)
    wide[:, ::2] = o  # a strided view: converted to a contiguous copy
    np.testing.assert_array_equal(runtime.trace(wide[:, ::2], d.astype(np.float64), tmin, tmax), want)


def test_a_bad_ray_past_the_first_chunk_is_named(wave):
    runtime = runtime_or_skip(wave, "bvh2", threads=2)
    o, d, tmin, tmax = rays(wave[0], (5000,), seed=2)
    d[4990] = 0.0
    tmax[1030] = np.nan
    for query in (runtime.trace, runtime.occluded):
        with pytest.raises(tsah.ConfigError, match=r"^rays: ray 1030: tmax is NaN$"):
            query(o, d, tmin, tmax)


def test_bench_prints_the_ratio():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, str(BENCH), "--triangles", "2000", "--rays", "5000", "--runs", "1",
                           "--layout", "bvh4"], capture_output=True, text=True, env=env, check=True)
    cpu = json.loads(done.stdout)["cpu"]
    assert cpu["rays"] == 5000 and cpu["layout"] == "bvh4" and cpu["hits"] > 0
    assert cpu["cxx_batch_ms"] == min(cpu["arrays_batch_ms"], cpu["struct_batch_ms"]) > 0
    assert cpu["rate_ratio"] == pytest.approx(cpu["cxx_batch_ms"] / cpu["python_ms"])
