"""Arguments the command line refuses are refused in Python too, with tsah.ConfigError in the
library's words (parameter names, never command-line flags): the limits of --frames, --eval-frames,
--fps, --k, --time-limit, --min-improvement and --seed are the same C++ constants; NaN, infinite and
negative numbers, NaN rays, and float64 values that float32 cannot hold. Also run against the ASan
build (ctest python.asan in the debug-asan preset)."""
import math

import numpy as np
import pytest

import tsah

NAN, INF = float("nan"), float("inf")


@pytest.fixture(scope="module")
def tree(sample):
    return tsah.optimize(sample, method="sah0")


@pytest.fixture(scope="module")
def runtime(tree, sample):
    return tsah.CpuRuntime(tree, sample)


def refused(call, message):
    with pytest.raises(tsah.ConfigError, match=message) as caught:
        call()
    assert "--" not in str(caught.value), str(caught.value)  # no command-line flags


def test_eval_frames_is_capped_as_on_the_command_line(sample, tree):
    refused(lambda: tree.costs(sample, eval_frames=100001), r"eval_frames: must be in 1\.\.100000, not 100001")
    refused(lambda: tree.costs(sample, eval_frames=10**9), r"eval_frames: must be in 1\.\.100000")
    refused(lambda: tree.costs(sample, eval_frames=0), r"eval_frames: must be in 1\.\.100000, not 0")
    refused(lambda: tsah.evaluate(sample, "sah0", eval_frames=100001), r"eval_frames: must be in 1\.\.100000")
    assert tree.costs(sample, eval_frames=3).shape == (3,)


def test_the_tree_options_are_checked_as_on_the_command_line(sample):
    for call, message in [
        (lambda: tsah.optimize(sample, frames=1001), r"frames: must be in 1\.\.1000, not 1001"),
        (lambda: tsah.optimize(sample, frames=0), r"frames: must be in 1\.\.1000, not 0"),
        (lambda: tsah.evaluate(sample, "sah0", frames=1001), r"frames: must be in 1\.\.1000"),
        (lambda: tsah.optimize(sample, k=99), r"k must be in 0\.\.16, not 99"),
        (lambda: tsah.optimize(sample, k=-1), r"k must be in 0\.\.16, not -1"),
        (lambda: tsah.optimize(sample, method="tsah99"), r"method 'tsah99': the T-SAH exponent k must be in 0\.\.16"),
        (lambda: tsah.evaluate(sample, "sah0,tsah17"), r"method 'tsah17': the T-SAH exponent k must be in 0\.\.16"),
        (lambda: tsah.optimize(sample, time_limit=NAN), r"time_limit: must be a finite number"),
        (lambda: tsah.optimize(sample, time_limit=INF), r"time_limit: must be a finite number"),
        (lambda: tsah.optimize(sample, time_limit=-1.0), r"time_limit: must be a finite number"),
        (lambda: tsah.evaluate(sample, "sah0", time_limit=NAN), r"time_limit: must be a finite number"),
        (lambda: tsah.optimize(sample, min_improvement=NAN), r"min_improvement: must be in \[0, 1\]"),
        (lambda: tsah.optimize(sample, min_improvement=1.5), r"min_improvement: must be in \[0, 1\]"),
        (lambda: tsah.optimize(sample, ct=NAN), r"cT and cI must be finite and positive"),
        (lambda: tsah.optimize(sample, ci=INF), r"cT and cI must be finite and positive"),
        (lambda: tsah.optimize(sample, max_leaf=257), r"maximum leaf size must be in 1\.\.256"),
        (lambda: tsah.optimize(sample, seed=-1), r"seed: must be in 0\.\.18446744073709551615, not -1"),
        (lambda: tsah.optimize(sample, seed=2**64), r"seed: must be in 0\.\.18446744073709551615"),
        (lambda: tsah.optimize(sample, threads=-1), r"threads: must be in 0\.\.4294967295, not -1"),
        (lambda: tsah.evaluate(sample, "sah0", seed=-1), r"seed: must be in"),
        (lambda: tsah.generate("wave", triangles=-1), r"triangles: must be in"),
        (lambda: tsah.generate("wave", seed=-5), r"seed: must be in"),
    ]:
        refused(call, message)


def test_an_int_argument_of_another_type_is_an_argument_type_error(sample):
    with pytest.raises(tsah.ArgumentTypeError, match="seed: expected an int, got float"):
        tsah.optimize(sample, seed=1.5)
    with pytest.raises(tsah.ArgumentTypeError, match="frames: expected an int, got str"):
        tsah.optimize(sample, frames="5")


def test_cost_constants_are_checked(sample, tree):
    refused(lambda: tree.costs(sample, ct=NAN), r"costs: the cost constants cT and cI must be finite and positive")
    refused(lambda: tree.costs(sample, ci=-2.0), r"costs: the cost constants cT and cI must be finite and positive")
    refused(lambda: tree.frame_costs(ct=INF), r"frame_costs: the cost constants")
    refused(lambda: tree.costs(sample, threads=-1), r"threads: must be in")


def test_fps_is_checked_as_on_the_command_line(sample_path):
    for fps in (NAN, INF, -1.0, 10000.5):
        refused(lambda: tsah.load(sample_path, fps=fps), r"fps: must be in \[0, 10000\]")
    assert tsah.load(sample_path, fps=10000.0).triangle_count > 0


def test_times_must_be_finite(sample, runtime):
    refused(lambda: runtime.refit(NAN), r"time: must be a finite time, not nan")
    refused(lambda: runtime.refit(-INF), r"time: must be a finite time, not -inf")
    refused(lambda: sample.positions_at(NAN), r"t: must be a finite time")
    refused(lambda: sample.segment(NAN, 1.0), r"t0: must be a finite time")
    refused(lambda: sample.segment(0.0, INF), r"t1: must be a finite time")
    runtime.refit(sample.end_time)


def test_frame_counts_of_an_animation_are_capped(sample):
    refused(lambda: sample.uniform_times(0), r"n: must be in 1\.\.1000000, not 0")
    refused(lambda: sample.uniform_times(2**32), r"n: must be in 1\.\.1000000")
    refused(lambda: sample.resample(1000001), r"n: must be in 1\.\.1000000")
    assert sample.uniform_times(3).shape == (3,)


def test_refit_positions_must_be_finite(runtime):
    positions = np.zeros((runtime_vertices(runtime), 3), np.float32)
    positions[1, 2] = np.nan
    with pytest.raises(tsah.DataError, match=r"positions: vertex 1 has a NaN or infinite coordinate"):
        runtime.refit_positions(positions)


def test_runtime_threads_are_checked(tree, sample):
    refused(lambda: tsah.CpuRuntime(tree, sample, threads=-1), r"threads: must be in 0\.\.4294967295, not -1")


def one_ray(origin=(0.0, 0.0, -10.0), direction=(0.0, 0.0, 1.0)):
    return np.array([origin], np.float32), np.array([direction], np.float32)


@pytest.mark.parametrize("origin, direction, tmin, tmax, message", [
    ((0, 0, -10), (0, NAN, 1), 0.0, INF, "ray 0: direction is not finite"),
    ((0, 0, -10), (INF, 0, 1), 0.0, INF, "ray 0: direction is not finite"),
    ((NAN, 0, -10), (0, 0, 1), 0.0, INF, "ray 0: origin is not finite"),
    ((0, 0, -10), (0, 0, 0), 0.0, INF, "ray 0: direction is zero"),
    ((0, 0, -10), (0, 0, 1), NAN, INF, "ray 0: tmin must be finite and >= 0"),
    ((0, 0, -10), (0, 0, 1), -1.0, INF, "ray 0: tmin must be finite and >= 0"),
    ((0, 0, -10), (0, 0, 1), 0.0, NAN, "ray 0: tmax is NaN"),
])
def test_rays_that_cannot_be_traced_are_refused(runtime, origin, direction, tmin, tmax, message):
    origins, directions = one_ray(origin, direction)
    for query in (runtime.trace, runtime.occluded):
        refused(lambda: query(origins, directions, tmin, tmax), "rays: " + message)


def test_the_bad_ray_is_named_by_its_index(runtime):
    origins = np.zeros((4, 3), np.float32)
    directions = np.ones((4, 3), np.float32)
    directions[2, 1] = np.nan
    refused(lambda: runtime.trace(origins, directions, tmin=np.zeros(4, np.float32)), "rays: ray 2: direction")
    tmax = np.full(4, np.inf, np.float32)
    tmax[3] = np.nan
    directions[2, 1] = 1.0
    refused(lambda: runtime.occluded(origins, directions, tmax=tmax), "rays: ray 3: tmax is NaN")


def test_float64_values_that_float32_cannot_hold_are_refused(runtime):
    triangles = np.array([[0, 1, 2]], np.uint32)
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float64)
    for value, word in ((1e-40, "underflows"), (-1e-39, "underflows"), (1e39, "overflows"), (-3.5e38, "overflows")):
        bad = positions.copy()
        bad[1, 2] = value
        refused(lambda: tsah.Animation(triangles, bad), rf"positions: value .* \(index 5\) {word} float32")
    # Small but normal float32, and a model above the smallest supported extent (1e-18): kept.
    small = positions * 1e-12
    assert tsah.Animation(triangles, small).positions[0, 1, 0] == np.float32(1e-12)
    origins, directions = one_ray()
    refused(lambda: runtime.trace(origins.astype(np.float64) * 1e39, directions), r"origins: value .* overflows float32")
    refused(lambda: runtime.trace(origins, directions.astype(np.float64) * 1e-300),
            r"directions: value .* underflows float32")
    refused(lambda: runtime.refit_positions(np.full((runtime_vertices(runtime), 3), 1e-45)),
            r"positions: value .* underflows float32")


def runtime_vertices(runtime):
    """The vertex count of the runtime's animation, read from the error of a wrong shape."""
    with pytest.raises(tsah.ConfigError) as caught:
        runtime.refit_positions(np.zeros((0, 3), np.float32))
    return int(str(caught.value).split("expected shape (")[1].split(",")[0])


def test_values_at_the_limits_are_accepted(sample):
    tree = tsah.optimize(sample, frames=2, k=16, time_limit=0.0, min_improvement=1.0, seed=2**64 - 1, max_leaf=256)
    assert tree.node_count > 0 and math.isfinite(tree.costs(sample, eval_frames=2).sum())
