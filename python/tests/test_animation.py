"""Animations: loading, numpy round trips against the command line's files, and input checks."""
import numpy as np
import pytest

import tsah


def test_load_matches_cli_info(cli, sample, sample_path):
    info = cli.json("info", sample_path)
    assert sample.keyframe_count == info["frames"] == 10
    assert sample.triangle_count == info["triangles"]
    assert sample.vertex_count == info["vertices"]
    assert (sample.start_time, sample.end_time) == tuple(info["time"])
    np.testing.assert_array_equal(sample.bounds, np.array(info["bounds"], dtype=np.float32))
    assert sample.positions.shape == (10, sample.vertex_count, 3)
    assert sample.positions.dtype == np.float32
    assert sample.triangles.shape == (sample.triangle_count, 3)
    assert sample.triangles.dtype == np.uint32


def test_resample_matches_cli_tanim_bytes(cli, sample, sample_path, tmp_path):
    cli.run("resample", sample_path, "-o", tmp_path / "cli.tanim", "--frames", 5)
    sample.resample(5).save(str(tmp_path / "py.tanim"))
    assert (tmp_path / "py.tanim").read_bytes() == (tmp_path / "cli.tanim").read_bytes()
    back = tsah.load(str(tmp_path / "cli.tanim"))
    np.testing.assert_array_equal(back.positions, sample.resample(5).positions)
    np.testing.assert_array_equal(back.times, np.linspace(sample.start_time, sample.end_time, 5))


def test_animation_from_numpy_round_trips_through_tanim(cli, sample, tmp_path):
    copy = tsah.Animation(sample.triangles.astype(np.int64), sample.positions.astype(np.float64), sample.times,
                          name="copy")
    np.testing.assert_array_equal(copy.positions, sample.positions)
    np.testing.assert_array_equal(copy.triangles, sample.triangles)
    np.testing.assert_array_equal(copy.positions_at(2.5), sample.positions_at(2.5))
    path = tmp_path / "copy.tanim"
    copy.save(str(path))
    info = cli.json("info", path)
    assert (info["frames"], info["triangles"], info["vertices"]) == (10, sample.triangle_count, sample.vertex_count)
    back = tsah.load(str(path))
    np.testing.assert_array_equal(back.positions, sample.positions)
    np.testing.assert_array_equal(back.times, sample.times)


def test_positions_at_interpolates():
    tri = np.array([[0, 1, 2]])
    p0 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    a = tsah.Animation(tri, np.stack([p0, p0 + 2]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(a.positions_at(0.25), p0 + 0.5)
    np.testing.assert_array_equal(a.positions_at(-1.0), p0)  # clamped
    single = tsah.Animation(tri, p0)  # one frame as (V, 3)
    assert single.keyframe_count == 1 and single.times.tolist() == [0.0]


def test_missing_and_corrupt_files_raise_the_cli_message(cli, sample_path, tmp_path):
    missing = str(tmp_path / "nothing.obj")
    with pytest.raises(tsah.FileError) as caught:
        tsah.load(missing)
    assert str(caught.value) == cli.error("info", missing)
    assert isinstance(caught.value, tsah.Error) and isinstance(caught.value, RuntimeError)

    good = tmp_path / "good.tanim"
    cli.run("resample", sample_path, "-o", good, "--frames", 3)
    data = bytearray(good.read_bytes())
    for name, broken in [("truncated.tanim", data[: len(data) // 2]),
                         ("flipped.tanim", data[:40] + bytes([data[40] ^ 0xFF]) + data[41:])]:
        path = tmp_path / name
        path.write_bytes(bytes(broken))
        with pytest.raises(tsah.FileError) as caught:
            tsah.load(str(path))
        assert str(caught.value) == cli.error("info", path)
        assert str(caught.value).startswith(str(path) + ": ")


def test_wrong_types_and_shapes_raise_clear_errors():
    tri = np.array([[0, 1, 2]], dtype=np.uint32)
    pos = np.zeros((2, 3, 3), dtype=np.float32)
    pos[:, 1, 0] = 1
    pos[:, 2, 1] = 1
    with pytest.raises(TypeError, match="triangles: expected an integer array, got dtype float64"):
        tsah.Animation(tri.astype(np.float64), pos)
    with pytest.raises(TypeError, match="positions: expected a floating-point array"):
        tsah.Animation(tri, pos.astype(np.int32))
    assert tsah.Animation(tri, pos.tolist()).positions.tolist() == pos.tolist()  # lists are arrays too
    with pytest.raises(TypeError, match="positions: expected a numpy array, got str"):
        tsah.Animation(tri, "positions")
    with pytest.raises(TypeError, match="positions"):
        tsah.Animation(tri, pos.astype(np.complex64))
    with pytest.raises(ValueError, match=r"triangles: expected shape \(N, 3\), got \(1, 4\)"):
        tsah.Animation(np.zeros((1, 4), dtype=np.int32), pos)
    with pytest.raises(ValueError, match=r"positions: expected shape \(N, N, 3\), got \(2, 3, 2\)"):
        tsah.Animation(tri, pos[:, :, :2])
    with pytest.raises(ValueError, match="triangles: value -1 is out of range"):
        tsah.Animation(np.array([[0, 1, -1]]), pos)
    with pytest.raises(ValueError, match="out of range"):
        tsah.Animation(np.array([[0, 1, 2**40]]), pos)
    with pytest.raises(ValueError, match="times: expected 2 times"):
        tsah.Animation(tri, pos, np.array([0.0, 1.0, 2.0]))
    # Consistent types and shapes, inconsistent content: the library's own one-line errors.
    with pytest.raises(tsah.Error):
        tsah.Animation(np.array([[0, 1, 7]]), pos)  # index past the vertices
    with pytest.raises(tsah.Error):
        tsah.Animation(tri, pos, np.array([1.0, 0.0]))  # times not increasing
    bad = pos.copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(tsah.Error):
        tsah.Animation(tri, bad)
    # Non-contiguous input is accepted (copied).
    a = tsah.Animation(tri, np.asfortranarray(pos))
    np.testing.assert_array_equal(a.positions, pos)


def test_scene_subdividing_a_flipped_face_raises_data_error(tmp_path):
    # A tetrahedron whose last face is wound inwards: refused before the subdivider sees it.
    (tmp_path / "flipped.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 4 3\n")
    scene = tmp_path / "s.json"
    scene.write_text('{"objects": [{"name": "rock", "file": "flipped.obj", "subdivide": 3}]}')
    with pytest.raises(tsah.DataError, match=r"object 'rock': .*not consistently oriented"):
        tsah.load(str(scene))
