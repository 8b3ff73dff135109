"""The library side of the module: tree sets as `tsah optimize --segments` builds them, Ctrl-C and
progress callbacks during long calls, pickling, the argument forms accepted (os.PathLike, lists,
numpy scalars) and messages in the library's words."""
import copy
import importlib.util
import os
import pathlib
import pickle
import time

import numpy as np
import pytest

import tsah

SOURCE_DIR = pathlib.Path(os.environ.get("TSAH_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))


@pytest.mark.parametrize("segments,extra", [(3, ["--overlap", 0.5]), ("auto", ["--budget", 1.2])])
def test_tree_set_matches_cli_bytes_and_costs(cli, sample, sample_path, tmp_path, segments, extra):
    out = tmp_path / "cli.tbvh"
    report = cli.json("optimize", sample_path, "-o", out, "--segments", segments, "--eval-frames", 12,
                      "--reproducible", *extra)
    keywords = {"overlap": 0.5} if segments == 3 else {"budget": 1.2}
    trees = tsah.optimize(sample, segments=segments, eval_frames=12, reproducible=True, **keywords)
    assert isinstance(trees, tsah.TreeSet)
    assert trees.to_bytes() == out.read_bytes()
    trees.save(tmp_path / "python.tbvh")
    assert (tmp_path / "python.tbvh").read_bytes() == out.read_bytes()
    assert len(trees) == report["trees"]
    assert trees.segmentation["costs"].tolist() == report["cost"]["per_frame"]
    assert trees.costs(sample, eval_frames=12).tolist() == report["cost"]["per_frame"]
    assert [p[:2] for p in trees.segmentation["parts"]] == [(p["time_start"], p["time_end"]) for p in report["parts"]]
    assert [t.node_count for t in trees] == [p["nodes"] for p in report["parts"]]
    assert trees.info["segmentation"] == report["segmentation"]

    read = tsah.read_tree(out)  # a set file reads as a TreeSet
    assert isinstance(read, tsah.TreeSet) and read.to_bytes() == out.read_bytes()
    assert read.ranges == trees.ranges and read.segmentation is None
    assert read.tree_at(trees.switch_times[0]) == 1 and read.tree_at(-1e9) == 0
    assert read[-1].to_bytes() == read[len(read) - 1].to_bytes()
    with pytest.raises(IndexError):
        read[len(read)]


def test_a_tree_file_reads_as_a_tree(sample, tmp_path):
    tree = tsah.optimize(sample, method="sah0")
    tree.save(tmp_path / "one.tbvh")
    assert isinstance(tsah.read_tree(tmp_path / "one.tbvh"), tsah.Tree)
    assert isinstance(tsah.tree_from_bytes(tree.to_bytes()), tsah.Tree)


def test_tree_set_options_in_the_librarys_words(sample):
    for call, message in [
        (lambda: tsah.optimize(sample, overlap=1.0), "overlap: goes with segments"),
        (lambda: tsah.optimize(sample, segments=2, budget=1.1), "budget: goes with segments auto"),
        (lambda: tsah.optimize(sample, segments="many"), "segments: expected a number of trees or 'auto'"),
        (lambda: tsah.optimize(sample, segments=0), "segments: must be in 1..1000"),
        (lambda: tsah.optimize(sample, segments="auto", budget=1.1, budget_cost=50), "give one of them"),
        (lambda: tsah.optimize(sample, segments=2, max_trees=4), "max_trees: goes with segments='auto'"),
        (lambda: tsah.optimize(sample, segments=2, eval_frames=1), "eval_frames: a tree set needs 2.."),
    ]:
        with pytest.raises(tsah.ConfigError, match=message) as caught:
            call()
        assert "--" not in str(caught.value)
    still = tsah.Animation(sample.triangles, sample.positions[0])
    with pytest.raises(tsah.DataError, match="a tree set needs an animation"):
        tsah.optimize(still, segments=2)


def test_optimizer_gpu_or_a_config_error_naming_the_parameter(sample):
    try:
        tree = tsah.optimize(sample, seed=6, optimizer="gpu")
    except tsah.ConfigError as caught:
        assert str(caught).startswith("optimizer='gpu': ") and "--" not in str(caught)
        assert not tsah.cuda_built or not tsah.cuda_available()
        return
    assert tree.info["selection"] == "parallel-cuda"


def test_generate_limits_in_the_librarys_words():
    with pytest.raises(tsah.ConfigError) as caught:
        tsah.generate("wave", triangles=0)
    assert str(caught.value) == "generate: triangles must be between 1 and 50,000,000"


# Ctrl-C: the signal comes from another thread while the call runs; KeyboardInterrupt must follow
# long before the call would end (each takes seconds without the cancel; the 5 s time limit bounds a
# failure). The target, under 0.2 s, is measured by python/bench/cancel_latency.py: a unit test on a
# loaded 2-core machine may see scheduling delays, so it asserts a bound of its own.
LATE = 1.5


def load_cancel_bench():
    spec = importlib.util.spec_from_file_location("cancel_latency", SOURCE_DIR / "python/bench/cancel_latency.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


cancel_bench = load_cancel_bench()


@pytest.fixture(scope="module")
def big():
    return tsah.generate("explode", triangles=100000, frames=10)


@pytest.mark.parametrize("call", ["optimize_sequential", "optimize_parallel", "tree_set", "evaluate"])
def test_ctrl_c_stops_long_calls_long_before_they_end(big, call):
    assert cancel_bench.seconds_to_interrupt(cancel_bench.calls(tsah, big)[call]) < LATE


def test_the_module_works_after_an_interruption(big, sample):
    cancel_bench.seconds_to_interrupt(cancel_bench.calls(tsah, big)["optimize_parallel"])
    assert tsah.optimize(sample, method="sah0").node_count > 0


def test_progress_is_called_with_batches_and_messages(sample):
    events = []
    tree = tsah.optimize(sample, seed=2, progress=events.append)
    assert [e["batch"] for e in events] == [h["batch"] for h in tree.optimization["history"]]
    assert events[-1]["cost"] == tree.optimization["final_cost"] and "message" in events[-1]
    messages = []
    tsah.evaluate(sample, "sah0,tsah0", eval_frames=5, progress=lambda e: messages.append(e["message"]))
    assert messages and all(isinstance(m, str) for m in messages)
    sets = []
    tsah.optimize(sample, segments=2, eval_frames=6, progress=sets.append)
    assert sets and all("message" in e for e in sets)
    with pytest.raises(tsah.ArgumentTypeError, match="progress: expected a callable"):
        tsah.optimize(sample, progress=3)


def test_an_exception_in_progress_cancels_the_call_and_propagates(big):
    class Stop(Exception):
        pass

    calls = []

    def progress(event):
        calls.append(time.monotonic())
        if len(calls) == 3:
            raise Stop("enough")

    start = time.monotonic()
    with pytest.raises(Stop, match="enough"):
        tsah.optimize(big, optimizer="parallel", min_improvement=0, time_limit=5, progress=progress)
    assert len(calls) == 3 and time.monotonic() - calls[-1] < LATE, time.monotonic() - start


def test_pickle_round_trips(sample):
    tree = tsah.optimize(sample, seed=4)
    for copied in (pickle.loads(pickle.dumps(tree)), copy.deepcopy(tree)):
        assert isinstance(copied, tsah.Tree) and copied.to_bytes() == tree.to_bytes()
        assert copied.info == tree.info and copied.costs(sample).tolist() == tree.costs(sample).tolist()
    trees = tsah.optimize(sample, segments=2, eval_frames=8)
    copied = pickle.loads(pickle.dumps(trees))
    assert isinstance(copied, tsah.TreeSet) and copied.to_bytes() == trees.to_bytes()
    assert copied.costs(sample, eval_frames=8).tolist() == trees.segmentation["costs"].tolist()


def test_bytes_in_memory_are_data_not_a_file(sample):
    data = tsah.optimize(sample, method="sah0").to_bytes()
    with pytest.raises(tsah.DataError, match="^<bytes>: ") as caught:
        tsah.tree_from_bytes(data[:-1])
    assert not isinstance(caught.value, tsah.FileError)
    with pytest.raises(tsah.DataError) as caught:
        pickle.loads(pickle.dumps(tsah.optimize(sample, method="sah0")).replace(data[100:140], bytes(40)))
    assert not isinstance(caught.value, tsah.FileError)


def test_paths_lists_and_numpy_scalars_are_accepted(sample_path, tmp_path):
    animation = tsah.load(pathlib.Path(sample_path), fps=np.float64(0))
    animation.save(tmp_path / "a.tanim")
    assert tsah.load(tmp_path / "a.tanim").vertex_count == animation.vertex_count
    tree = tsah.optimize(animation, method="sah0", frames=np.int32(3), seed=np.uint64(2), max_leaf=np.int64(4),
                         ct=np.float32(3), threads=np.int16(1))
    assert tree.frame_count == 3 and tree.info["seed"] == 2
    tree.save(tmp_path / "t.tbvh")
    assert tsah.read_tree(tmp_path / "t.tbvh").to_bytes() == tree.to_bytes()
    assert tsah.evaluate(animation, ["sah0"], eval_frames=np.uint8(4))["eval_frames"] == 4
    assert tsah.evaluate(animation, ("sah0", "tsah0"), eval_frames=4)["methods"][1]["name"] == "tsah0"
    lists = tsah.Animation([[0, 1, 2]], [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], times=[0.5])
    assert lists.triangle_count == 1 and lists.times.tolist() == [0.5]
    assert tsah.generate("wave", triangles=np.int64(200), frames=np.uint32(3)).keyframe_count == 3
    with pytest.raises(tsah.ArgumentTypeError, match="path: expected a str or os.PathLike path, got int"):
        tsah.read_tree(3)
    with pytest.raises(tsah.ArgumentTypeError, match="seed: expected an int, got float"):
        tsah.optimize(animation, seed=1.5)
    for flag, name in [(True, "bool"), (np.True_, "bool_")]:
        with pytest.raises(tsah.ArgumentTypeError, match=f"frames: expected an int, got {name}$"):
            tsah.optimize(animation, frames=flag)
