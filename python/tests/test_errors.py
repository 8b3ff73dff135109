"""The error classes: one per kind of mistake (libtsah/include/tsah/base/error.hpp), each also the
Python exception a caller would expect (ValueError for bad arguments and data, RuntimeError for
failures, TypeError for wrong types)."""
import re

import numpy as np
import pytest

import tsah


def test_the_classes_and_their_bases():
    assert issubclass(tsah.Error, RuntimeError)
    for cls in (tsah.ConfigError, tsah.DataError, tsah.Failure):
        assert issubclass(cls, tsah.Error) and issubclass(cls, RuntimeError), cls
    assert issubclass(tsah.ConfigError, ValueError)
    assert issubclass(tsah.DataError, ValueError)
    assert issubclass(tsah.FileError, tsah.DataError)
    assert issubclass(tsah.FileError, ValueError) and issubclass(tsah.FileError, tsah.Error)
    assert not issubclass(tsah.Failure, ValueError)
    assert not issubclass(tsah.ConfigError, tsah.DataError) and not issubclass(tsah.DataError, tsah.ConfigError)
    assert not issubclass(tsah.FileError, tsah.ConfigError) and not issubclass(tsah.Failure, tsah.DataError)
    assert issubclass(tsah.ArgumentTypeError, tsah.ConfigError) and issubclass(tsah.ArgumentTypeError, TypeError)
    for cls in (tsah.Error, tsah.ConfigError, tsah.DataError, tsah.FileError, tsah.Failure, tsah.ArgumentTypeError):
        assert cls.__module__ == "tsah" and cls.__doc__, cls
        assert getattr(tsah, cls.__name__) is cls and cls.__name__ in tsah.__all__


def test_a_bad_option_is_a_config_error(sample):
    for call in (lambda: tsah.optimize(sample, selection="best"),
                 lambda: tsah.optimize(sample, method="fastest"),
                 lambda: tsah.optimize(sample, max_leaf=0),
                 lambda: tsah.evaluate(sample, "sah0,nonsense"),
                 lambda: tsah.generate("spiral")):
        with pytest.raises(tsah.ConfigError) as caught:
            call()
        assert isinstance(caught.value, ValueError) and isinstance(caught.value, tsah.Error)
        assert not isinstance(caught.value, tsah.DataError)
    with pytest.raises(tsah.ConfigError, match="unknown node selection 'best'"):
        tsah.optimize(sample, selection="best")


def test_a_wrong_shape_is_a_config_error_and_a_wrong_dtype_also_a_type_error():
    with pytest.raises(tsah.ConfigError, match=r"triangles: expected shape \(N, 3\), got \(1, 4\)"):
        tsah.Animation(np.zeros((1, 4), dtype=np.uint32), np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(tsah.ArgumentTypeError) as caught:
        tsah.Animation(np.zeros((1, 3), dtype=np.float64), np.zeros((3, 3), dtype=np.float32))
    assert isinstance(caught.value, TypeError) and isinstance(caught.value, tsah.ConfigError)
    assert str(caught.value) == "triangles: expected an integer array, got dtype float64"


def test_a_corrupt_tree_file_is_a_file_error(sample, tmp_path):
    data = tsah.optimize(sample, method="sah0").to_bytes()
    path = tmp_path / "corrupt.tbvh"
    path.write_bytes(data[:200] + bytes([data[200] ^ 1]) + data[201:])
    for call in (lambda: tsah.read_tree(str(path)), lambda: tsah.read_tree(path)):
        with pytest.raises(tsah.FileError) as caught:
            call()
        assert isinstance(caught.value, tsah.DataError) and isinstance(caught.value, ValueError)
        assert isinstance(caught.value, tsah.Error) and not isinstance(caught.value, tsah.ConfigError)
    with pytest.raises(tsah.FileError, match="^" + re.escape(str(path)) + ": "):
        tsah.read_tree(str(path))


def test_unusable_data_is_a_data_error(sample):
    empty = tsah.Animation(np.zeros((0, 3), dtype=np.uint32), np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(tsah.DataError, match="no triangles") as caught:
        tsah.optimize(empty)
    assert isinstance(caught.value, ValueError) and not isinstance(caught.value, tsah.FileError)
    wave = tsah.generate("wave", triangles=200, frames=3)
    with pytest.raises(tsah.DataError, match="was not built for"):
        tsah.CpuRuntime(tsah.optimize(wave, method="sah0"), sample)


def test_a_failed_write_is_a_failure(sample, tmp_path):
    tree = tsah.optimize(sample, method="sah0")
    with pytest.raises(tsah.Failure, match="does not exist") as caught:
        tree.save(str(tmp_path / "no-such-folder" / "tree.tbvh"))
    assert isinstance(caught.value, RuntimeError) and not isinstance(caught.value, ValueError)
