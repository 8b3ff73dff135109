"""Closest points and box overlap: the C++ runtimes against brute force in numpy over every
triangle, in every CPU layout and after a refit; the GPU against the CPU; input checks."""
import numpy as np
import pytest

import tsah


@pytest.fixture(scope="module")
def wave():
    animation = tsah.generate("wave", triangles=600, frames=6, seed=2)
    return animation, tsah.optimize(animation, seed=1, max_leaf=4)


def closest_on_triangles(p, a, b, c):
    """Distance from each point (Q, 3) to each triangle (T, 3) in float64: (Q, T). The minimum
    over the face's plane projection when it falls inside, else over the three edges."""
    p = p[:, None, :]

    def segment(s0, s1):
        d = s1 - s0
        t = np.clip(np.einsum("qtk,tk->qt", p - s0, d) / np.maximum(np.einsum("tk,tk->t", d, d), 1e-300), 0, 1)
        return np.linalg.norm(p - (s0 + t[..., None] * d), axis=2)

    n = np.cross(b - a, c - a)
    n2 = np.einsum("tk,tk->t", n, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.einsum("qtk,tk->qt", p - a, n) / n2
        q = p - h[..., None] * n
        inside = np.ones(h.shape, bool)
        for s0, s1 in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("qtk,tk->qt", np.cross(s1 - s0, q - s0), n) >= 0
        face = np.where(inside & (n2 > 0), np.abs(h) * np.sqrt(n2), np.inf)
    return np.minimum(face, np.minimum(segment(a, b), np.minimum(segment(b, c), segment(c, a))))


def layouts():
    return ["bvh2", "bvh4", "bvh8"]


def runtime_in(tree, animation, layout):
    try:
        return tsah.CpuRuntime(tree, animation, layout=layout)
    except tsah.ConfigError as e:  # bvh8 needs AVX2
        assert layout == "bvh8" and "AVX2" in str(e)
        pytest.skip("no AVX2")


@pytest.mark.parametrize("layout", layouts())
def test_closest_points_and_overlap_match_brute_force(wave, layout):
    animation, tree = wave
    runtime = runtime_in(tree, animation, layout)
    rng = np.random.default_rng(4)
    for time in (animation.start_time, 0.5 * (animation.start_time + animation.end_time), animation.end_time):
        runtime.refit(time)
        p = animation.positions_at(time).astype(np.float64)
        a, b, c = (p[animation.triangles[:, i]] for i in range(3))
        lo, hi = p.min(axis=0), p.max(axis=0)
        diagonal = float(np.linalg.norm(hi - lo))
        points = (lo - 0.2 * (hi - lo) + rng.random((300, 3)) * 1.4 * (hi - lo)).astype(np.float32)
        radius = np.where(np.arange(300) % 4 == 0, np.inf, diagonal * rng.uniform(0.01, 0.2, 300)).astype(np.float32)
        dist = closest_on_triangles(points.astype(np.float64), a, b, c)
        want = dist.min(axis=1)
        got = runtime.closest_points(points, radius)
        assert got.dtype.names == ("distance", "triangle", "u", "v", "point")
        inside = want <= radius * (1 - 1e-5)
        outside = want > radius * (1 + 1e-5)
        assert inside.any() and outside.any()
        assert np.all(got["triangle"][inside] >= 0)
        assert np.all(got["triangle"][outside] == -1) and np.all(np.isinf(got["distance"][outside]))
        np.testing.assert_allclose(got["distance"][inside], want[inside], rtol=1e-5, atol=1e-6 * diagonal)
        # The triangle reported lies at that distance (ties between triangles are allowed).
        hit = np.flatnonzero(inside)
        np.testing.assert_allclose(dist[hit, got["triangle"][hit]], want[hit], rtol=1e-5, atol=1e-6 * diagonal)
        t = got["triangle"][hit]
        u, v = got["u"][hit, None].astype(np.float64), got["v"][hit, None].astype(np.float64)
        np.testing.assert_allclose((1 - u - v) * a[t] + u * b[t] + v * c[t], got["point"][hit], atol=1e-5 * diagonal)
        # Every point without a limit finds something.
        assert np.all(got["triangle"][np.isinf(radius)] >= 0)

        centres = lo + rng.random((100, 3)) * (hi - lo)
        half = rng.random((100, 3)) * 0.1 * diagonal
        qlo, qhi = (centres - half).astype(np.float32), (centres + half).astype(np.float32)
        offsets, ids = runtime.overlapping_triangles(qlo, qhi)
        tlo = np.minimum(np.minimum(a, b), c).astype(np.float32)
        thi = np.maximum(np.maximum(a, b), c).astype(np.float32)
        assert offsets.shape == (101,) and offsets[0] == 0 and offsets[-1] == len(ids) > 0
        for i in range(100):
            expect = np.flatnonzero(np.all((tlo <= qhi[i]) & (qlo[i] <= thi), axis=1))
            np.testing.assert_array_equal(ids[offsets[i]:offsets[i + 1]], expect)


def test_query_inputs_are_checked(wave):
    animation, tree = wave
    runtime = tsah.CpuRuntime(tree, animation)
    points = np.zeros((2, 3), np.float32)
    with pytest.raises(tsah.ConfigError, match="radius"):
        runtime.closest_points(points, -1.0)
    with pytest.raises(tsah.ConfigError, match="radius"):
        runtime.closest_points(points, np.array([1.0, np.nan]))
    with pytest.raises(tsah.ConfigError, match="points"):
        runtime.closest_points(np.zeros((2, 2), np.float32))
    with pytest.raises(tsah.ConfigError, match="non-finite"):
        runtime.closest_points(np.array([[0, np.inf, 0]], np.float32))
    with pytest.raises(tsah.ConfigError, match="radius"):
        runtime.closest_points(points, np.ones(3, np.float32))
    with pytest.raises(TypeError):
        runtime.closest_points(np.array([["a", "b", "c"]]))
    with pytest.raises(tsah.ConfigError, match="lo > hi"):
        runtime.overlapping_triangles(np.ones((1, 3), np.float32), np.zeros((1, 3), np.float32))
    with pytest.raises(tsah.ConfigError, match="hi"):
        runtime.overlapping_triangles(np.zeros((2, 3), np.float32), np.zeros((1, 3), np.float32))
    assert len(runtime.closest_points(np.zeros((0, 3), np.float32))) == 0


@pytest.mark.skipif(not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)")
def test_gpu_queries_equal_cpu(wave):
    animation, tree = wave
    cpu, gpu = tsah.CpuRuntime(tree, animation, layout="bvh2"), tsah.GpuRuntime(tree, animation)
    rng = np.random.default_rng(5)
    time = 0.3 * animation.end_time + 0.7 * animation.start_time
    cpu.refit(time)
    gpu.refit(time)
    p = animation.positions_at(time)
    lo, hi = p.min(axis=0), p.max(axis=0)
    points = (lo + rng.random((500, 3)) * (hi - lo)).astype(np.float32)
    radius = float(np.linalg.norm(hi - lo)) * 0.05
    want, got = cpu.closest_points(points, radius), gpu.closest_points(points, radius)
    np.testing.assert_array_equal(got["triangle"], want["triangle"])
    np.testing.assert_allclose(got["distance"], want["distance"], rtol=1e-5)
    qlo, qhi = points - radius, points + radius
    for w, g in zip(cpu.overlapping_triangles(qlo, qhi), gpu.overlapping_triangles(qlo, qhi)):
        np.testing.assert_array_equal(g, w)
