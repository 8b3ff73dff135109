"""Two-level scenes from Python: tsah.build_two_level / load_two_level and TwoLevelScene.save (the
command line's files), TwoLevelRuntime traced against a flat tree of the baked scene, misses,
argument errors, blurred frames, and GpuTwoLevelRuntime against TwoLevelRuntime (on a GPU only)."""
import json
import os
import pathlib
import pickle

import numpy as np
import pytest

import tsah
from device_lib import LIB, needs_device_arrays, new_stream, synchronize, to_device, to_host

SOURCE_DIR = pathlib.Path(os.environ.get("TSAH_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))

DEMO = SOURCE_DIR / "samples" / "scenes" / "demo.json"
EXPLODE = SOURCE_DIR / "samples" / "explode"

needs_gpu = pytest.mark.skipif(not (tsah.cuda_built and tsah.cuda_available()), reason="needs a CUDA device")


@pytest.fixture(scope="module")
def scene():
    return tsah.build_two_level(DEMO, structure="two-level")


@pytest.fixture(scope="module")
def baked():
    return tsah.load(DEMO)


def rays_to_triangles(animation, time, count=400, eye=(0.5, 6.0, 14.0), seed=3):
    """Rays from `eye` toward the centroids of `count` triangles of the baked scene at `time`."""
    positions = animation.positions_at(time)
    triangles = animation.triangles
    pick = np.random.default_rng(seed).choice(len(triangles), size=count, replace=False)
    targets = positions[triangles[pick]].mean(axis=1)
    origins = np.broadcast_to(np.asarray(eye, np.float32), targets.shape).copy()
    return origins, (targets - origins).astype(np.float32)


def test_build_two_level_keeps_every_object_instanced(scene):
    assert scene.instance_count == 7  # ground, 4 pillars, 2 bursts
    assert scene.blas_count == 3
    assert scene.flattened_objects == []
    assert (scene.start_time, scene.end_time) == (0.0, 2.0)
    assert len(scene.frame_times) == 21 and scene.frame_times[0] == 0.0 and scene.frame_times[-1] == 2.0
    info = scene.info
    assert info["instances"] == 7 and len(info["blases"]) == 3 and info["poses"] >= 1
    assert info["bytes"]["total"] >= info["bytes"]["blas"] + info["bytes"]["tlas"]
    assert len(info["tlas"]["frame_costs"]) == 21 and "structure_choice" not in info


def test_auto_flattens_what_the_command_line_flattens(cli, tmp_path):
    scene = tsah.build_two_level(str(DEMO))  # a str path as well as a pathlib.Path
    choice = scene.info["structure_choice"]
    expected = cli.json("optimize", DEMO, "-o", tmp_path / "demo.tbvh")
    assert expected["structure"] == "two-level"
    assert scene.flattened_objects == expected["flattened_objects"]
    assert [o["flatten"] for o in choice["objects"]] == [o["flatten"] for o in expected["structure_choice"]["objects"]]
    assert scene.instance_count == expected["instances"]


def test_auto_weighs_the_whole_scene_as_the_command_line_does(cli, tmp_path):
    # Three overlapping bursts flattened by their own estimate, two small blocks beside them: the
    # whole scene as one tree costs less than the two levels (docs/two-level.md, rule 5).
    burst = str(EXPLODE / "explode_%04d.obj")
    block = str(EXPLODE / "explode_0001.obj")
    path = tmp_path / "whole.json"
    path.write_text(json.dumps({"fps": 5, "time": [0, 2], "objects": [
        {"name": "burst", "file": burst, "time": {"speed": 4, "outside": "loop"}, "instances": [
            {"transform": {"scale": [1, 1, -1]}},
            {"offset": 0.3, "path": [{"time": 0, "translate": [-3, 0, 0]}, {"time": 2, "translate": [3, 0, 0]}]},
            {"offset": 0.3, "transform": {"translate": [0, 3, 0], "rotate": [30, 0, 0]}}]},
        {"name": "block", "file": block, "instances": [
            {"transform": {"translate": [0, -2, 0], "scale": [4, 0.3, 4]}},
            {"transform": {"translate": [4, 0, 0], "rotate": [0, 30, 0]}}]}]}))
    scene = tsah.build_two_level(path)
    choice = scene.info["structure_choice"]
    whole = choice["whole_scene_cost"]
    assert 0 < whole["flattened"] <= whole["decided"]
    assert [o["flatten"] for o in choice["objects"]] == [True, True]
    assert scene.instance_count == 1 and scene.flattened_objects == ["burst", "block"]
    expected = cli.json("info", path, "--structure")
    assert expected["structure"] == "flat"
    assert expected["whole_scene_cost"] == pytest.approx(whole)


@pytest.fixture(scope="module")
def parts():
    return tsah.build_two_level(DEMO, structure="two-level", tlas_trees=4)


def test_tlas_trees(scene, parts, tmp_path):
    tlas = parts.info["tlas"]
    assert tlas["trees"] == 4 and len(tlas["frame_costs"]) == 21
    assert tlas["ranges"] == [(0.0, 0.5), (0.5, 1.0), (1.0, 1.5), (1.5, 2.0)]
    path = tmp_path / "parts.tbvh"
    parts.save(path)
    assert tsah.load_two_level(path, DEMO).info["tlas"]["ranges"] == tlas["ranges"]
    # The same hits as the scene's own TLAS, on a boundary and inside a part.
    baked = tsah.load(DEMO)
    a, b = tsah.TwoLevelRuntime(scene), tsah.TwoLevelRuntime(parts)
    for time in (0.5, 1.2, 2.0):
        a.update(time)
        b.update(time)
        origins, directions = rays_to_triangles(baked, time)
        assert np.array_equal(a.trace(origins, directions), b.trace(origins, directions))
    for bad, message in ((0, "tlas_trees: expected 'auto' or a number of trees >= 1, got 0"),
                         ("many", "tlas_trees: expected 'auto'"), (True, "got True"),
                         (5000, "tlas_trees: 5000 is more than 4096")):
        with pytest.raises(tsah.ConfigError, match=message):
            tsah.build_two_level(DEMO, tlas_trees=bad)
    with pytest.raises(tsah.ConfigError, match="tlas_budget: 0.5"):
        tsah.build_two_level(DEMO, tlas_budget=0.5)


def test_save_and_load_round_trip(scene, tmp_path):
    path = tmp_path / "demo.tbvh"
    scene.save(path)
    loaded = tsah.load_two_level(path, DEMO)
    assert loaded.instance_count == scene.instance_count and loaded.blas_count == scene.blas_count
    origins, directions = rays_to_triangles(tsah.load(DEMO), 0.6)
    a, b = tsah.TwoLevelRuntime(scene), tsah.TwoLevelRuntime(loaded)
    a.update(0.6)
    b.update(0.6)
    assert np.array_equal(a.trace(origins, directions), b.trace(origins, directions))


def test_pickle_round_trip_loads_the_sources_again(scene, tmp_path, monkeypatch):
    copy = pickle.loads(pickle.dumps(scene))
    assert repr(copy) == repr(scene) and copy.flattened_objects == scene.flattened_objects
    scene.save(tmp_path / "a.tbvh")
    copy.save(tmp_path / "b.tbvh")
    assert (tmp_path / "a.tbvh").read_bytes() == (tmp_path / "b.tbvh").read_bytes()
    origins, directions = rays_to_triangles(tsah.load(DEMO), 1.3)
    a, b = tsah.TwoLevelRuntime(scene), tsah.TwoLevelRuntime(copy)
    a.update(1.3)
    b.update(1.3)
    assert np.array_equal(a.trace(origins, directions), b.trace(origins, directions))
    # The scene's path is kept absolute: another working directory unpickles the same scene.
    relative = tsah.build_two_level(os.path.relpath(DEMO), structure="auto")
    data = pickle.dumps(relative)
    monkeypatch.chdir(tmp_path)
    moved = pickle.loads(data)
    assert moved.flattened_objects == relative.flattened_objects and moved.instance_count == relative.instance_count


def test_a_pickle_whose_scene_changed_or_went_is_refused(scene, tmp_path):
    # A scene file of its own (absolute source paths), so that it can be changed and removed.
    description = json.loads(DEMO.read_text())
    for o in description["objects"]:
        o["file"] = str((DEMO.parent / o["file"]).resolve())
    own = tmp_path / "own.json"
    own.write_text(json.dumps(description))
    data = pickle.dumps(tsah.build_two_level(own, structure="two-level"))
    description["objects"][1]["instances"].pop()  # one pillar less
    own.write_text(json.dumps(description))
    with pytest.raises(tsah.DataError, match="<pickle> was not built for .*own.json: "):
        pickle.loads(data)
    own.unlink()
    with pytest.raises(tsah.FileError, match="own.json"):
        pickle.loads(data)
    state = scene.__getstate__()
    broken = bytearray(state[1])
    broken[100:108] = b"\xff" * 8
    with pytest.raises(tsah.DataError, match="<pickle>: "):
        tsah.TwoLevelScene.__new__(tsah.TwoLevelScene).__setstate__((state[0], bytes(broken)))
    with pytest.raises(tsah.DataError, match="expected a TwoLevelScene's state"):
        tsah.TwoLevelScene.__new__(tsah.TwoLevelScene).__setstate__(("x",))


def test_the_command_lines_file_loads_and_traces_as_the_built_scene(cli, scene, tmp_path):
    path = tmp_path / "cli.tbvh"
    cli.run("optimize", DEMO, "--structure", "two-level", "-o", path)
    loaded = tsah.load_two_level(str(path), str(DEMO))
    origins, directions = rays_to_triangles(tsah.load(DEMO), 1.3)
    a, b = tsah.TwoLevelRuntime(scene), tsah.TwoLevelRuntime(loaded)
    a.update(1.3)
    b.update(1.3)
    assert np.array_equal(a.trace(origins, directions), b.trace(origins, directions))


@pytest.mark.parametrize("layout", ["bvh2", "bvh4", "auto"])
def test_trace_matches_a_flat_tree_of_the_baked_scene(scene, baked, layout):
    time = float(scene.frame_times[7])  # a scene frame: the bake's keyframe there is exact
    flat = tsah.CpuRuntime(tsah.optimize(baked, method="sah0"), baked)
    flat.refit(time)
    runtime = tsah.TwoLevelRuntime(scene, layout=layout)
    runtime.update(time)
    assert runtime.time == time
    origins, directions = rays_to_triangles(baked, time)
    expected = flat.trace(origins, directions)
    hits = runtime.trace(origins, directions)
    assert hits.dtype.names == ("t", "u", "v", "instance", "triangle")
    assert np.array_equal(np.isfinite(hits["t"]), expected["triangle"] >= 0)
    assert (expected["triangle"] >= 0).mean() > 0.9
    hit = expected["triangle"] >= 0
    ids = scene.baked_triangles(hits["instance"][hit], hits["triangle"][hit])
    assert (ids == expected["triangle"][hit]).mean() > 0.99
    np.testing.assert_allclose(hits["t"][hit], expected["t"][hit], rtol=1e-4)
    assert np.array_equal(runtime.occluded(origins, directions), hit)


@pytest.mark.parametrize("layout", ["bvh4", "auto"])
def test_pose_triangles_as_woop_or_vertices_find_the_same_hits(scene, baked, layout):
    woop = tsah.TwoLevelRuntime(scene, layout=layout, pose_triangles="woop")
    vertices = tsah.TwoLevelRuntime(scene, layout=layout)  # the default: vertex packets
    for time in (scene.start_time, float(scene.frame_times[5]), 1.3):
        woop.update(time)
        vertices.update(time)
        origins, directions = rays_to_triangles(baked, time)
        a, b = woop.trace(origins, directions), vertices.trace(origins, directions)
        assert np.isfinite(a["t"]).mean() > 0.9
        assert np.array_equal(np.isfinite(a["t"]), np.isfinite(b["t"]))
        same = (a["instance"] == b["instance"]) & (a["triangle"] == b["triangle"])
        assert same.mean() > 0.99
        np.testing.assert_allclose(b["t"][same], a["t"][same], rtol=1e-4)
        assert np.array_equal(woop.occluded(origins, directions), vertices.occluded(origins, directions))
    assert vertices.memory_bytes < woop.memory_bytes  # vertex packets are smaller than Woop packets


def test_misses_are_inf_and_minus_one(scene):
    runtime = tsah.TwoLevelRuntime(scene)
    origins = np.array([[0, 50, 0], [0, 0, 0]], np.float32)
    directions = np.array([[0, 1, 0], [0, -1, 0]], np.float32)
    hits = runtime.trace(origins, directions, tmax=np.array([np.inf, 1e-3]))
    assert np.all(np.isinf(hits["t"])) and np.all(hits["instance"] == -1) and np.all(hits["triangle"] == -1)
    assert np.all(hits["u"] == 0) and np.all(hits["v"] == 0)
    assert not runtime.occluded(origins, directions, tmax=np.array([np.inf, 1e-3])).any()


def test_batch_shapes_and_out(scene, baked):
    runtime = tsah.TwoLevelRuntime(scene)
    origins, directions = rays_to_triangles(baked, scene.start_time, count=24)
    flat = runtime.trace(origins, directions)
    out = np.empty((4, 6), flat.dtype)
    hits = runtime.trace(origins.reshape(4, 6, 3), directions.reshape(4, 6, 3), out=out)
    assert hits is out and np.array_equal(out.reshape(-1), flat)
    occluded = np.empty((4, 6), bool)
    assert runtime.occluded(origins.reshape(4, 6, 3), directions.reshape(4, 6, 3), out=occluded) is occluded
    assert np.array_equal(occluded.reshape(-1), np.isfinite(flat["t"]))


def test_bad_arguments(scene, tmp_path):
    runtime = tsah.TwoLevelRuntime(scene)
    ok = np.zeros((3, 3), np.float32)
    with pytest.raises(tsah.ConfigError, match=r"origins: expected shape \(\.\.\., 3\), got \(3, 2\)"):
        runtime.trace(np.zeros((3, 2), np.float32), ok)
    with pytest.raises(tsah.ArgumentTypeError, match="directions: expected a floating-point array, got dtype int64"):
        runtime.trace(ok, np.zeros((3, 3), np.int64))
    with pytest.raises(tsah.ConfigError, match=r"times: expected shape \(3,\), got \(2,\)"):
        runtime.trace(ok, ok + 1, times=np.zeros(2))
    with pytest.raises(tsah.ConfigError, match="times: value nan .index 1. is not a finite shutter fraction"):
        runtime.occluded(ok, ok + 1, times=np.array([0, np.nan, 0]))
    with pytest.raises(tsah.ArgumentTypeError, match="out: expected dtype"):
        runtime.trace(ok, ok + 1, out=np.zeros(3, np.float32))
    with pytest.raises(tsah.ConfigError, match="time: must be a finite time"):
        runtime.update(float("nan"))
    with pytest.raises(tsah.ConfigError):
        runtime.update_shutter(1.0, 0.5)
    with pytest.raises(tsah.ConfigError, match="layout: cwbvh is a GPU layout"):
        tsah.TwoLevelRuntime(scene, layout="cwbvh")
    with pytest.raises(tsah.ConfigError, match="tlas: expected 'refit' or 'rebuild', got 'lbvh'"):
        tsah.TwoLevelRuntime(scene, tlas="lbvh")
    with pytest.raises(tsah.ConfigError, match="pose_triangles: unknown triangle form 'quads' .expected woop or vertices."):
        tsah.TwoLevelRuntime(scene, pose_triangles="quads")
    with pytest.raises(tsah.ArgumentTypeError, match="scene: expected a tsah.TwoLevelScene, got str"):
        tsah.TwoLevelRuntime("demo.json")
    with pytest.raises(tsah.ConfigError, match="structure: expected 'auto' or 'two-level', got 'flat'"):
        tsah.build_two_level(DEMO, structure="flat")
    with pytest.raises(tsah.ConfigError, match="optimizer: a two-level scene is built on the CPU"):
        tsah.build_two_level(DEMO, optimizer="gpu")
    with pytest.raises(tsah.ConfigError, match="instances: value 7 .index 0. is not an instance"):
        scene.baked_triangles([7], [0])
    with pytest.raises(tsah.FileError, match="nothing.json"):
        tsah.build_two_level(tmp_path / "nothing.json")


def test_a_tree_of_another_scene_is_refused(scene, tmp_path):
    tree = tmp_path / "demo.tbvh"
    scene.save(tree)
    description = json.loads(DEMO.read_text())
    for o in description["objects"]:
        o["file"] = str((DEMO.parent / o["file"]).resolve())
    description["objects"][1]["instances"].pop()  # one pillar fewer
    other = tmp_path / "other.json"
    other.write_text(json.dumps(description))
    with pytest.raises(tsah.DataError, match=f"{tree} was not built for {other}"):
        tsah.load_two_level(tree, other)
    flat = tmp_path / "flat.tbvh"
    tsah.optimize(tsah.load(EXPLODE), method="sah0").save(flat)
    with pytest.raises(tsah.FileError, match=str(flat)):
        tsah.load_two_level(flat, DEMO)


def test_blurred_frame_traces_each_ray_at_its_time(scene, baked):
    runtime = tsah.TwoLevelRuntime(scene)
    runtime.update_shutter(0.5, 0.7)
    assert runtime.blurred and runtime.time == 0.7
    for fraction, time in ((0.0, 0.5), (1.0, 0.7)):
        still = tsah.TwoLevelRuntime(scene)
        still.update(time)
        origins, directions = rays_to_triangles(baked, time)
        expected = still.trace(origins, directions)
        hits = runtime.trace(origins, directions, times=np.full(len(origins), fraction, np.float32))
        assert np.array_equal(hits, runtime.trace(origins, directions, times=fraction))
        assert np.array_equal(hits, runtime.trace(origins, directions, times=[fraction] * len(origins)))
        assert np.array_equal(hits, runtime.trace(origins, directions, times=np.float32(fraction)))
        found = np.isfinite(expected["t"])
        assert found.mean() > 0.9 and (np.isfinite(hits["t"]) == found).mean() > 0.99
        same = (hits["instance"] == expected["instance"]) & (hits["triangle"] == expected["triangle"])
        assert same[found].mean() > 0.99
        np.testing.assert_allclose(hits["t"][same & found], expected["t"][same & found], rtol=1e-3)
        assert np.array_equal(runtime.occluded(origins, directions, times=fraction), np.isfinite(hits["t"]))
    # The burst instances move between the shutter's ends: the two ends differ somewhere.
    origins, directions = rays_to_triangles(baked, 0.6)
    open_, close = (runtime.trace(origins, directions, times=f) for f in (0.0, 1.0))
    assert not np.array_equal(open_, close)
    runtime.update(0.7)
    assert not runtime.blurred


def test_instance_boxes_and_memory(scene):
    runtime = tsah.TwoLevelRuntime(scene, threads=1, layout="bvh2", tlas="rebuild")
    boxes = runtime.instance_boxes
    assert boxes.shape == (7, 2, 3) and boxes.dtype == np.float32 and np.all(boxes[:, 0] <= boxes[:, 1])
    runtime.update(2.0)
    assert not np.array_equal(runtime.instance_boxes, boxes)  # the bursts moved
    assert runtime.memory_bytes > 0


@needs_gpu
@pytest.mark.parametrize("layout", ["bvh2", "cwbvh"])
@pytest.mark.parametrize("tlas", ["refit", "lbvh", "hlbvh-sah", "refit-parts"])
def test_gpu_two_level_runtime_matches_the_cpu(scene, parts, baked, tlas, layout):
    if tlas == "refit-parts":  # a TLAS per part of the time: each refitted in its part
        scene, tlas = parts, "refit"
    gpu = tsah.GpuTwoLevelRuntime(scene, layout=layout, tlas=tlas)
    cpu = tsah.TwoLevelRuntime(scene, layout="bvh2")
    for time in (0.0, 0.75, 1.0, 2.0):
        gpu.update(time)
        cpu.update(time)
        assert gpu.time == time and gpu.last_update["instances"] == 7
        origins, directions = rays_to_triangles(baked, time)
        expected = cpu.trace(origins, directions)
        hits = gpu.trace(origins, directions)
        assert np.array_equal(np.isfinite(hits["t"]), np.isfinite(expected["t"]))
        same = (hits["instance"] == expected["instance"]) & (hits["triangle"] == expected["triangle"])
        assert same.mean() > 0.99
        np.testing.assert_allclose(hits["t"][same], expected["t"][same], rtol=1e-4)
        assert np.array_equal(gpu.occluded(origins, directions), cpu.occluded(origins, directions))


@needs_gpu
@pytest.mark.parametrize("layout", ["bvh2", "cwbvh"])
def test_gpu_blurred_frame_matches_the_cpu(scene, baked, layout):
    gpu = tsah.GpuTwoLevelRuntime(scene, layout=layout)
    cpu = tsah.TwoLevelRuntime(scene, layout="bvh2")
    gpu.update_shutter(0.5, 0.7)
    cpu.update_shutter(0.5, 0.7)
    assert gpu.blurred and gpu.time == 0.7
    origins, directions = rays_to_triangles(baked, 0.6)
    times = np.linspace(0.0, 1.0, len(origins), dtype=np.float32)
    expected = cpu.trace(origins, directions, times=times)
    hits = gpu.trace(origins, directions, times=times)
    assert np.array_equal(np.isfinite(hits["t"]), np.isfinite(expected["t"]))
    same = (hits["instance"] == expected["instance"]) & (hits["triangle"] == expected["triangle"])
    assert same.mean() > 0.99
    np.testing.assert_allclose(hits["t"][same], expected["t"][same], rtol=1e-5)
    assert np.array_equal(gpu.occluded(origins, directions, times=times), cpu.occluded(origins, directions, times=times))
    gpu.update(0.7)
    assert not gpu.blurred


@needs_device_arrays
def test_gpu_device_arrays_equal_the_host_path(scene, baked):
    gpu = tsah.GpuTwoLevelRuntime(scene)
    gpu.update(0.75)
    origins, directions = rays_to_triangles(baked, 0.75)
    origins, directions = origins.reshape(20, 20, 3), directions.reshape(20, 20, 3)
    tmax = np.full((20, 20), np.inf, np.float32)
    tmax[0] = 1.0  # short rays: some miss
    expected = gpu.trace(origins, directions, tmax=tmax)
    stream = new_stream()
    with (LIB.cuda.stream(stream) if LIB.__name__ == "torch" else stream):
        given = stream if LIB.__name__ == "torch" else stream.ptr
        hits = gpu.trace(to_device(origins), to_device(directions), tmax=to_device(tmax), stream=given)
        flags = gpu.occluded(to_device(origins), to_device(directions), tmax=to_device(tmax), stream=given)
    stream.synchronize()
    assert sorted(hits) == ["instance", "t", "triangle", "u", "v"]
    for field in ("t", "u", "v", "instance", "triangle"):
        np.testing.assert_array_equal(to_host(hits[field]), expected[field])
    assert 0 < (expected["instance"] >= 0).sum() < expected.size
    np.testing.assert_array_equal(to_host(flags), gpu.occluded(origins, directions, tmax=tmax))

    # A blurred frame: per-ray times as a device array or one number; results into the caller's arrays.
    gpu.update_shutter(0.5, 0.7)
    times = np.linspace(0.0, 1.0, 400, dtype=np.float32).reshape(20, 20)
    expected = gpu.trace(origins, directions, times=times)
    out = {"instance": to_device(np.zeros((20, 20), np.int32)), "t": to_device(np.zeros((20, 20), np.float32))}
    assert gpu.trace(to_device(origins), to_device(directions), times=to_device(times), out=out) is out
    flags = tsah.DeviceArray((20, 20), "|b1")
    assert gpu.occluded(to_device(origins), to_device(directions), times=0.25, out=flags) is flags
    synchronize()
    np.testing.assert_array_equal(to_host(out["instance"]), expected["instance"])
    np.testing.assert_array_equal(to_host(out["t"]), expected["t"])
    np.testing.assert_array_equal(to_host(flags), gpu.occluded(origins, directions, times=np.full((20, 20), 0.25, np.float32)))

    with pytest.raises(tsah.ConfigError, match="out: unknown field 'prim' .t, u, v, instance, triangle."):
        gpu.trace(to_device(origins), to_device(directions), out={"prim": out["t"]})
    with pytest.raises(tsah.ConfigError, match=r"times: expected shape \(20, 20\), got \(400,\)"):
        gpu.trace(to_device(origins), to_device(directions), times=to_device(times.ravel()))
    with pytest.raises(tsah.ArgumentTypeError, match="times: expected None, a number or a float32 device array"):
        gpu.trace(to_device(origins), to_device(directions), times=times)


@pytest.mark.skipif(not tsah.cuda_built, reason="a build without CUDA has no GpuTwoLevelRuntime")
def test_gpu_two_level_runtime_refuses_an_unknown_tlas_update_or_a_cpu_layout(scene):
    with pytest.raises(tsah.ConfigError, match="tlas: unknown TLAS update 'bvh' .refit, lbvh or hlbvh-sah."):
        tsah.GpuTwoLevelRuntime(scene, tlas="bvh")
    with pytest.raises(tsah.ConfigError, match="layout: bvh8 is a CPU layout .the GPU's are bvh2 and cwbvh."):
        tsah.GpuTwoLevelRuntime(scene, layout="bvh8")


def test_an_uninitialised_scene_is_refused(scene):
    bare = tsah.TwoLevelScene.__new__(tsah.TwoLevelScene)
    with pytest.raises(tsah.ConfigError, match="tsah.TwoLevelScene is not initialised"):
        tsah.TwoLevelRuntime(bare)
    with pytest.raises(tsah.ConfigError, match="tsah.TwoLevelScene is not initialised"):
        bare.instance_count
