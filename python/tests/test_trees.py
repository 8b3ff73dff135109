"""Trees: the same .tbvh bytes as `tsah optimize` for the same seed, the same costs as
`tsah optimize --json` and `tsah evaluate --json`, .tbvh round trips and bad files."""
import numpy as np
import pytest

import tsah

BUILD_SECONDS = slice(88, 96)  # header field f64 buildSeconds (docs/tbvh-format.md): a timing


def same_tree_bytes(a: bytes, b: bytes):
    """Equal files apart from the build time and the CRC-32 that covers it."""
    assert len(a) == len(b)
    assert a[:BUILD_SECONDS.start] == b[:BUILD_SECONDS.start]
    assert a[BUILD_SECONDS.stop:-4] == b[BUILD_SECONDS.stop:-4]


@pytest.mark.parametrize("method,seed", [("tsah", 3), ("sah0", 1), ("sahstar", 2)])
def test_optimize_matches_cli_bytes_and_costs(cli, sample, sample_path, tmp_path, method, seed):
    out = tmp_path / "cli.tbvh"
    report = cli.json("optimize", sample_path, "-o", out, "--method", method, "--seed", seed)
    tree = tsah.optimize(sample, method=method, seed=seed)
    same_tree_bytes(tree.to_bytes(), out.read_bytes())
    assert tree.node_count == report["nodes"] and tree.depth == report["depth"]
    assert tree.leaf_count == report["leaves"] and tree.frame_count == 5
    costs = tree.costs(sample, eval_frames=50)
    assert costs.shape == (50,)
    assert costs.tolist() == report["cost"]["per_frame"]
    if method == "tsah":
        assert tree.optimization["final_cost"] == report["optimization"]["final_cost"]
        assert tree.optimization["final_cost"] <= tree.optimization["initial_cost"]
    else:
        assert tree.optimization is None


def test_optimizer_gpu_matches_cli_or_says_why_not(cli, sample, sample_path, tmp_path):
    with pytest.raises(ValueError, match="optimizer"):
        tsah.optimize(sample, optimizer="tpu")
    try:
        tree = tsah.optimize(sample, seed=6, optimizer="gpu")
    except tsah.ConfigError as caught:  # a build without CUDA, or no device: in the module's own words
        assert str(caught).startswith("optimizer='gpu': ")
        return
    out = tmp_path / "cuda.tbvh"
    report = cli.json("optimize", sample_path, "-o", out, "--device", "cuda", "--seed", 6)
    same_tree_bytes(tree.to_bytes(), out.read_bytes())  # the GPU optimizer is deterministic too
    assert tree.info["selection"] == "parallel-cuda" and report["device"] == "cuda"
    assert tree.optimization["final_cost"] <= tree.optimization["initial_cost"]


@pytest.mark.parametrize("threads", [1, 2])
def test_parallel_optimizer_matches_cli_for_any_thread_count(cli, sample, sample_path, tmp_path, threads):
    out = tmp_path / "parallel.tbvh"
    report = cli.json("optimize", sample_path, "-o", out, "--optimizer", "parallel", "--threads", 2, "--seed", 6)
    tree = tsah.optimize(sample, seed=6, optimizer="parallel", threads=threads)
    same_tree_bytes(tree.to_bytes(), out.read_bytes())  # the same tree for 1 and 2 threads
    assert tree.info["selection"] == "parallel" and report["selection"] == "parallel"
    assert tree.optimization["final_cost"] == report["optimization"]["final_cost"]
    assert tree.optimization["final_cost"] <= tree.optimization["initial_cost"]
    assert tree.costs(sample, eval_frames=50).tolist() == report["cost"]["per_frame"]
    table = tsah.evaluate(sample, "tsah0", eval_frames=50, seed=6, optimizer="parallel", threads=threads)
    assert table["methods"][0]["per_frame"].tolist() == report["cost"]["per_frame"]
    sequential = tsah.optimize(sample, seed=6)
    assert sequential.info["selection"] == "mh"
    assert tree.to_bytes()[96:] != sequential.to_bytes()[96:]


def test_tree_file_round_trip(cli, sample, sample_path, tmp_path):
    out = tmp_path / "cli.tbvh"
    cli.run("optimize", sample_path, "-o", out, "--k", 2, "--max-leaf", 4, "--seed", 5)
    tree = tsah.read_tree(str(out))
    assert tree.to_bytes() == out.read_bytes()
    info = cli.json("info", out)
    for key in ["method", "selection", "k", "representative_frames", "seed", "max_leaf_size", "triangles",
                "vertices", "topology_hash"]:
        assert tree.info[key] == info[key], key
    assert tree.info["build_s"] == pytest.approx(info["build_s"])
    copy = tmp_path / "copy.tbvh"
    tree.save(str(copy))
    assert copy.read_bytes() == out.read_bytes()
    assert tsah.tree_from_bytes(out.read_bytes()).to_bytes() == out.read_bytes()
    assert sorted(tree.triangle_order.tolist()) == list(range(sample.triangle_count))


def test_evaluate_matches_cli_json(cli, sample, sample_path):
    methods = "sah0,sahstar,tsah0,tsah2,rebuild"
    expected = cli.json("evaluate", sample_path, "--methods", methods, "--eval-frames", 20, "--seed", 4)
    got = tsah.evaluate(sample, methods.split(","), eval_frames=20, seed=4)
    for key in ["triangles", "frames", "eval_frames", "max_leaf", "ct", "ci"]:
        assert got[key] == expected[key], key
    assert [m["name"] for m in got["methods"]] == methods.split(",")
    for mine, theirs in zip(got["methods"], expected["methods"]):
        assert mine["average"] == theirs["average"] and mine["maximum"] == theirs["maximum"]
        assert mine["per_frame"].tolist() == theirs["per_frame"]
    # T-SAH k=0 optimizes the average, so it is no worse on average than SAH0 on this scene.
    by_name = {m["name"]: m for m in got["methods"]}
    assert by_name["tsah0"]["average"] < by_name["sah0"]["average"]


def test_static_input_uses_one_frame(sample):
    static = tsah.Animation(sample.triangles, sample.positions[0])
    tree = tsah.optimize(static, frames=5)
    assert tree.frame_count == 1
    assert tree.costs(static).shape == (1,)
    np.testing.assert_allclose(tree.costs(static), tree.frame_costs())


def test_bad_trees_and_options_raise(cli, sample, sample_path, tmp_path):
    out = tmp_path / "good.tbvh"
    cli.run("optimize", sample_path, "-o", out, "--method", "sah0")
    data = out.read_bytes()
    cases = {"truncated.tbvh": data[:100], "crc.tbvh": data[:200] + bytes([data[200] ^ 1]) + data[201:],
             "empty.tbvh": b"", "missing.tbvh": None}
    for name, content in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(tsah.FileError) as caught:
            tsah.read_tree(str(path))
        assert str(caught.value).startswith(str(path) + ": ")
        # `tsah export` reads its first argument as a .tbvh whatever it holds.
        assert str(caught.value) == cli.error("export", path, sample_path, "-o", tmp_path / "export")
    with pytest.raises(tsah.DataError):
        tsah.tree_from_bytes(data[:-1])
    with pytest.raises(ValueError, match="unknown"):
        tsah.optimize(sample, method="fastest")
    with pytest.raises(ValueError, match="node selection"):
        tsah.optimize(sample, selection="best")
    with pytest.raises(ValueError, match="rebuild"):
        tsah.optimize(sample, method="rebuild")
    with pytest.raises(ValueError, match="unknown optimizer"):
        tsah.optimize(sample, optimizer="cuda")
    with pytest.raises(ValueError, match="unknown optimizer"):
        tsah.evaluate(sample, "tsah0", optimizer="fast")
    with pytest.raises(ValueError):
        tsah.evaluate(sample, "sah0,nonsense")
    with pytest.raises(TypeError):
        tsah.optimize(sample, frames="five")
    with pytest.raises(TypeError):
        tsah.optimize("not an animation")
    empty = tsah.Animation(np.zeros((0, 3), dtype=np.uint32), np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(tsah.Error, match="no triangles"):
        tsah.optimize(empty)
