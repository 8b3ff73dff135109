"""Runtimes: rays traced by the C++ runtime against a brute-force numpy reference, refits, the GPU
against the CPU (when a GPU is present), and input checks on ray arrays."""
import numpy as np
import pytest

import tsah

import device_lib


@pytest.fixture(scope="module")
def wave():
    animation = tsah.generate("wave", triangles=600, frames=6, seed=2)
    return animation, tsah.optimize(animation, seed=1, max_leaf=4)


def random_rays(animation, time, count, seed):
    """Rays from outside the frame's bounds towards random points inside them."""
    rng = np.random.default_rng(seed)
    p = animation.positions_at(time)
    lo, hi = p.min(axis=0), p.max(axis=0)
    size = float((hi - lo).max())
    targets = lo + rng.random((count, 3)) * (hi - lo)
    origins = targets + rng.normal(size=(count, 3)) * size
    return origins.astype(np.float32), (targets - origins).astype(np.float32)


def brute_force(points, triangles, origins, directions):
    """Nearest hit per ray over every triangle (Moller-Trumbore in float64): (t, triangle, margin),
    margin = how far the hit lies inside its triangle in barycentric terms and from the next hit."""
    v0, v1, v2 = (points[triangles[:, i]].astype(np.float64) for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    o, d = origins.astype(np.float64)[:, None, :], directions.astype(np.float64)[:, None, :]
    pvec = np.cross(d, e2)
    det = np.einsum("rtk,tk->rt", pvec, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tvec = o - v0
        u = np.einsum("rtk,rtk->rt", tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = np.einsum("rk,rtk->rt", directions.astype(np.float64), qvec) * inv
        t = np.einsum("tk,rtk->rt", e2, qvec) * inv
    inside = np.minimum(np.minimum(u, v), 1 - u - v)
    valid = (np.abs(det) > 1e-12) & (inside >= 0) & (t > 0)
    t = np.where(valid, t, np.inf)
    order = np.argsort(t, axis=1)
    rows = np.arange(len(origins))
    nearest, second = t[rows, order[:, 0]], t[rows, order[:, 1]]
    triangle = np.where(np.isfinite(nearest), order[:, 0], -1)
    with np.errstate(invalid="ignore"):
        gap = (second - nearest) / nearest
    margin = np.where(np.isfinite(nearest), np.minimum(inside[rows, order[:, 0]], gap), np.inf)
    return nearest, triangle, margin


# Every layout with the Woop triangles, and the wide layouts with vertex packets (bvh2 has no other form).
@pytest.mark.parametrize("layout,triangles", [("auto", "woop"), ("bvh2", "woop"), ("bvh4", "woop"), ("bvh8", "woop"),
                                              ("auto", "vertices"), ("bvh4", "vertices"), ("bvh8", "vertices")])
def test_trace_matches_brute_force(wave, layout, triangles):
    animation, tree = wave
    try:
        runtime = tsah.CpuRuntime(tree, animation, layout=layout, triangles=triangles)
    except tsah.ConfigError as e:  # bvh8 needs AVX2: a processor without it refuses that layout
        assert layout == "bvh8" and "AVX2" in str(e)
        pytest.skip(str(e))
    assert runtime.layout == layout or (layout == "auto" and runtime.layout in ("bvh4", "bvh8"))
    assert runtime.triangles == triangles
    for time in [animation.start_time, 2.3, animation.end_time]:
        runtime.refit(time)
        origins, directions = random_rays(animation, time, 400, seed=int(time * 10))
        hits = runtime.trace(origins, directions)
        assert hits.dtype.names == ("t", "u", "v", "triangle") and hits.shape == (400,)
        t, triangle, margin = brute_force(animation.positions_at(time), animation.triangles, origins, directions)
        robust = margin > 1e-4  # not within rounding of an edge or of a second surface
        assert robust.sum() > 300
        np.testing.assert_array_equal(hits["triangle"][robust], triangle[robust])
        hit = robust & (triangle >= 0)
        assert hit.sum() > 50
        np.testing.assert_allclose(hits["t"][hit], t[hit], rtol=1e-4)
        # Every reported hit lies on its triangle at (u, v) and on its ray at t.
        got = hits["triangle"] >= 0
        points = animation.positions_at(time)[animation.triangles[hits["triangle"][got]]]
        u, v = hits["u"][got, None], hits["v"][got, None]
        on_triangle = (1 - u - v) * points[:, 0] + u * points[:, 1] + v * points[:, 2]
        on_ray = origins[got] + hits["t"][got, None] * directions[got]
        np.testing.assert_allclose(on_triangle, on_ray, atol=1e-4)
        # A miss: t = inf, triangle -1, u = v = 0.
        assert (~got).sum() > 0
        assert np.all(np.isinf(hits["t"][~got])) and np.all(hits["triangle"][~got] == -1)
        assert np.all(hits["u"][~got] == 0) and np.all(hits["v"][~got] == 0)
        # Occlusion over the whole ray agrees with the closest hit.
        np.testing.assert_array_equal(runtime.occluded(origins, directions), got)


def test_cpu_layout_is_checked(wave):
    animation, tree = wave
    with pytest.raises(tsah.ConfigError, match="cwbvh is a GPU layout"):
        tsah.CpuRuntime(tree, animation, layout="cwbvh")
    with pytest.raises(tsah.ConfigError, match="bvh8"):  # the message lists the choices
        tsah.CpuRuntime(tree, animation, layout="bvh16")


def test_triangle_form_is_checked(wave):
    animation, tree = wave
    assert tsah.CpuRuntime(tree, animation).triangles == "woop"  # the default
    with pytest.raises(tsah.ConfigError, match="the bvh2 layout holds its triangles only as Woop triangles"):
        tsah.CpuRuntime(tree, animation, layout="bvh2", triangles="vertices")
    with pytest.raises(tsah.ConfigError, match="triangles: unknown triangle form 'quads' \\(expected woop or vertices\\)"):
        tsah.CpuRuntime(tree, animation, triangles="quads")


def test_tmax_and_refit_positions(wave):
    animation, tree = wave
    runtime = tsah.CpuRuntime(tree, animation)
    runtime.refit_positions(animation.positions_at(1.5))
    origins, directions = random_rays(animation, 1.5, 200, seed=7)
    by_positions = runtime.trace(origins, directions)
    runtime.refit(1.5)
    np.testing.assert_array_equal(runtime.trace(origins, directions), by_positions)
    # A segment that ends before the hit sees nothing; per-ray limits are honoured.
    hit = by_positions["triangle"] >= 0
    short = np.where(hit, by_positions["t"] * 0.5, np.inf).astype(np.float32)
    assert not (runtime.trace(origins, directions, tmax=short)["triangle"][hit] >= 0).any()
    assert (runtime.trace(origins, directions, tmin=0.0, tmax=1e30)["triangle"] == by_positions["triangle"]).all()


def test_tree_from_cli_file_traces_like_python_tree(cli, sample, sample_path, tmp_path):
    out = tmp_path / "cli.tbvh"
    cli.run("optimize", sample_path, "-o", out, "--seed", 1)
    origins, directions = random_rays(sample, 4.0, 300, seed=3)
    results = []
    for tree in [tsah.read_tree(str(out)), tsah.optimize(sample, seed=1)]:
        runtime = tsah.CpuRuntime(tree, sample, threads=1)
        runtime.refit(4.0)
        results.append(runtime.trace(origins, directions))
    np.testing.assert_array_equal(results[0], results[1])


def test_tree_of_another_animation_is_refused(wave, sample):
    _, tree = wave
    with pytest.raises(tsah.Error, match="was not built for 'explode'"):
        tsah.CpuRuntime(tree, sample)


@pytest.fixture(scope="module")
def wave_set():
    animation = tsah.generate("wave", triangles=600, frames=9, seed=4)
    return animation, tsah.optimize(animation, method="sah0", segments=3, eval_frames=9)


def set_times(animation, trees):
    """The start, each switch time and a hair before it, the middle of each part, the end."""
    times = [animation.start_time, animation.end_time]
    for s in trees.switch_times:
        times += [s, float(np.nextafter(s, -np.inf))]
    times += [0.5 * (r[0] + r[1]) for r in trees.ranges]
    return times


@pytest.mark.parametrize("layout", ["bvh2", "auto"])
def test_a_tree_set_traces_the_tree_of_each_time(wave_set, layout):
    """refit(time) picks the tree of the time's part: the same hits, bit for bit, as a runtime of that
    tree alone refitted to the same time; refit(positions) keeps the tree."""
    animation, trees = wave_set
    assert len(trees) == 3
    runtime = tsah.CpuRuntime(trees, animation, layout=layout)
    assert runtime.tree_index == 0
    for i, time in enumerate(set_times(animation, trees)):
        runtime.refit(time)
        assert runtime.tree_index == trees.tree_at(time), time
        alone = tsah.CpuRuntime(trees[trees.tree_at(time)], animation, layout=layout)
        alone.refit(time)
        origins, directions = random_rays(animation, time, 500, seed=20 + i)
        np.testing.assert_array_equal(runtime.trace(origins, directions), alone.trace(origins, directions))
        np.testing.assert_array_equal(runtime.occluded(origins, directions), alone.occluded(origins, directions))
    kept = runtime.tree_index
    runtime.refit(animation.positions_at(animation.start_time))
    assert runtime.tree_index == kept


def test_a_tree_set_of_another_animation_is_refused(wave_set, sample):
    _, trees = wave_set
    with pytest.raises(tsah.Error, match="tree 0 of the set was not built for 'explode'"):
        tsah.CpuRuntime(trees, sample)


@pytest.mark.skipif(not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)")
def test_a_tree_set_on_the_gpu_traces_as_on_the_cpu(wave_set):
    animation, trees = wave_set
    cpu, gpu = tsah.CpuRuntime(trees, animation, layout="bvh2"), tsah.GpuRuntime(trees, animation)
    for i, time in enumerate(set_times(animation, trees)):
        cpu.refit(time)
        gpu.refit(time)
        assert gpu.tree_index == cpu.tree_index == trees.tree_at(time), time
        origins, directions = random_rays(animation, time, 2000, seed=40 + i)
        a, b = cpu.trace(origins, directions), gpu.trace(origins, directions)
        assert (a["triangle"] == b["triangle"]).mean() > 0.999  # up to ties at equal distance
        np.testing.assert_allclose(a["t"], b["t"], rtol=1e-5)
        np.testing.assert_array_equal(cpu.occluded(origins, directions), gpu.occluded(origins, directions))


def test_wrong_ray_arrays_raise_clear_errors(wave):
    animation, tree = wave
    runtime = tsah.CpuRuntime(tree, animation)
    o = np.zeros((4, 3), dtype=np.float32)
    d = np.ones((4, 3), dtype=np.float32)
    with pytest.raises(TypeError, match="origins: expected a floating-point array, got dtype int64"):
        runtime.trace(o.astype(np.int64), d)
    with pytest.raises(TypeError, match="directions: expected a numpy array"):
        runtime.trace(o, [[1, 1, 1]] * 4)
    with pytest.raises(ValueError, match=r"origins: expected shape \(\.\.\., 3\), got \(4, 2\)"):
        runtime.trace(o[:, :2], d)
    with pytest.raises(ValueError, match=r"directions: expected the shape of origins \(4, 3\), got \(3, 3\)"):
        runtime.trace(o, d[:3])
    with pytest.raises(ValueError, match=r"tmax: expected shape \(4,\), got \(5,\)"):
        runtime.occluded(o, d, tmax=np.ones(5))
    with pytest.raises(TypeError, match="tmin"):
        runtime.trace(o, d, tmin="near")
    with pytest.raises(ValueError, match=r"positions: expected shape \(\d+, 3\)"):
        runtime.refit_positions(np.zeros((animation.vertex_count + 1, 3), dtype=np.float32))
    with pytest.raises(TypeError):
        runtime.refit_positions(np.zeros((animation.vertex_count, 3), dtype=np.int32))
    empty = runtime.trace(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.shape == (0,)
    # float64 and strided input are converted, not misread.
    strided = np.repeat(d.astype(np.float64), 2, axis=0)[::2]
    np.testing.assert_array_equal(runtime.trace(o, strided), runtime.trace(o, d))


@pytest.mark.skipif(not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)")
def test_gpu_matches_cpu(wave):
    animation, tree = wave
    cpu, gpu = tsah.CpuRuntime(tree, animation), tsah.GpuRuntime(tree, animation)
    for time in [0.0, 3.7]:
        cpu.refit(time)
        gpu.refit(time)
        origins, directions = random_rays(animation, time, 2000, seed=11)
        a, b = cpu.trace(origins, directions), gpu.trace(origins, directions)
        same = a["triangle"] == b["triangle"]
        assert same.mean() > 0.999  # the runtimes agree up to ties between triangles at equal distance
        np.testing.assert_allclose(a["t"], b["t"], rtol=1e-5)
        np.testing.assert_array_equal(cpu.occluded(origins, directions), gpu.occluded(origins, directions))


@pytest.mark.skipif(not tsah.cuda_built, reason="the CUDA runtime was not built")
def test_gpu_layout_names_a_gpu_layout(wave):
    animation, tree = wave
    with pytest.raises(tsah.ConfigError, match="layout: bvh8 is a CPU layout \\(the GPU's are bvh2 and cwbvh\\)"):
        tsah.GpuRuntime(tree, animation, layout="bvh8")
    with pytest.raises(tsah.ConfigError, match="layout"):
        tsah.GpuRuntime(tree, animation, layout="bvh16")


@pytest.mark.skipif(not tsah.cuda_available(), reason="no CUDA device (or the CUDA runtime was not built)")
@pytest.mark.parametrize("layout", ["auto", "bvh2", "cwbvh"])
def test_every_gpu_layout_traces_as_the_cpu(wave, layout):
    animation, tree = wave
    cpu, gpu = tsah.CpuRuntime(tree, animation, layout="bvh2"), tsah.GpuRuntime(tree, animation, layout=layout)
    assert gpu.layout == ("bvh2" if layout == "auto" else layout)
    for time in [0.0, 2.2]:
        cpu.refit(time)
        gpu.refit(time)
        origins, directions = random_rays(animation, time, 2000, seed=31)
        a, b = cpu.trace(origins, directions), gpu.trace(origins, directions)
        assert (a["triangle"] == b["triangle"]).mean() > 0.999  # up to ties at equal distance
        np.testing.assert_allclose(a["t"], b["t"], rtol=1e-5)
        np.testing.assert_array_equal(cpu.occluded(origins, directions), gpu.occluded(origins, directions))
        if device_lib.LIB is not None:  # device rays: the host batch's hits on the same layout
            hits = gpu.trace(device_lib.to_device(origins), device_lib.to_device(directions))
            np.testing.assert_array_equal(device_lib.to_host(hits["triangle"]), b["triangle"])
            np.testing.assert_array_equal(device_lib.to_host(hits["t"]), b["t"])


def test_rejected_calls_do_not_leak(wave):
    """Thousands of rejected calls leave the process's peak memory where it was."""
    import resource
    animation, tree = wave
    runtime = tsah.CpuRuntime(tree, animation)
    o, d = np.zeros((1000, 3), np.float32), np.ones((1000, 3), np.float32)
    calls = [lambda: runtime.trace(o.astype(np.int64), d), lambda: runtime.trace(o[:, :2], d),
             lambda: runtime.occluded(o, d, tmax=np.ones(3)), lambda: tsah.read_tree("/nonexistent.tbvh"),
             lambda: tsah.Animation(np.array([[0, 1, -1]]), animation.positions),
             lambda: tsah.Animation(np.array([[0, 1, 10**6]]), animation.positions)]

    def reject(rounds):
        for _ in range(rounds):
            for call in calls:
                with pytest.raises((TypeError, ValueError, tsah.Error)):
                    call()

    reject(300)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    reject(1500)  # 9,000 rejected calls: a leak of 100 bytes each would show as 0.9 MB
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 512  # KB
