"""Objects made with Class.__new__ and no __init__ hold no C++ object: every method, property and
function that receives one refuses it with tsah.ConfigError instead of running on uninitialised
memory. The classes, methods and functions are found by introspection, so a new one is covered.
Also run against the ASan build (ctest python.construction.asan in the debug-asan preset)."""
import re

import numpy as np
import pytest

import tsah
from tsah import _tsah

MAX_ARGUMENTS = 6  # more than any bound function takes


def bound_classes():
    return sorted((value for value in vars(_tsah).values()
                   if isinstance(value, type) and type(value).__name__ == "pybind11_type"),
                  key=lambda cls: cls.__name__)


def methods_and_properties(cls):
    """Names of the class's own C++ methods and properties (not __init__/__new__/__setstate__, which
    construct, object's, or those pybind11 adds to every class)."""
    names = []
    for name, value in vars(cls).items():
        if name in ("__init__", "__new__", "__setstate__", "__doc__", "__module__", "__dict__", "__weakref__"):
            continue
        if name.startswith("_pybind11_"):  # pybind11 3's own (the cross-module conduit), not ours
            continue
        if isinstance(value, property) or type(value).__name__ in ("instancemethod", "builtin_function_or_method"):
            names.append(name)
    return sorted(names)


def module_functions():
    return sorted((name for name, value in vars(_tsah).items()
                   if type(value).__name__ == "builtin_function_or_method"))


def is_not_initialised_error(error, cls):
    return isinstance(error, tsah.ConfigError) and f"tsah.{cls.__name__} is not initialised" in str(error)


def bare(cls):
    return cls.__new__(cls)


@pytest.fixture(scope="module")
def made(sample, sample_path):
    """A real instance of each class (for the methods that take a bare object as an argument)."""
    tree = tsah.optimize(sample, method="sah0")
    objects = {"Animation": sample, "Tree": tree, "CpuRuntime": tsah.CpuRuntime(tree, sample),
               "TreeSet": tsah.optimize(sample, method="sah0", segments=2, eval_frames=4)}
    scene = tsah.build_two_level(sample_path + "/../scenes/demo.json", structure="two-level")
    objects.update(TwoLevelScene=scene, TwoLevelRuntime=tsah.TwoLevelRuntime(scene))
    if tsah.cuda_built and tsah.cuda_available():
        objects["GpuRuntime"] = tsah.GpuRuntime(tree, sample)
        objects["GpuTwoLevelRuntime"] = tsah.GpuTwoLevelRuntime(scene)
    return objects


def test_the_module_binds_the_classes_this_file_expects():
    names = {cls.__name__ for cls in bound_classes()}
    assert {"Animation", "Tree", "TreeSet", "CpuRuntime"} <= names
    assert ("GpuRuntime" in names) == tsah.cuda_built


@pytest.mark.parametrize("cls", bound_classes(), ids=lambda cls: cls.__name__)
def test_every_method_and_property_of_an_uninitialised_object_is_refused(cls):
    names = methods_and_properties(cls)
    assert names, cls
    obj = bare(cls)
    for name in names:
        attribute = vars(cls)[name]
        if isinstance(attribute, property):
            with pytest.raises(tsah.ConfigError, match=f"tsah.{cls.__name__} is not initialised"):
                getattr(obj, name)
            continue
        # The object is checked before any other argument is looked at, so any argument count the
        # method accepts gives the error; the others are pybind11's "incompatible arguments".
        refused = False
        for count in range(MAX_ARGUMENTS + 1):
            try:
                getattr(obj, name)(*[None] * count)
            except tsah.ConfigError as error:
                assert is_not_initialised_error(error, cls), f"{cls.__name__}.{name}: {error}"
                refused = True
            except TypeError as error:
                assert "incompatible function arguments" in str(error), f"{cls.__name__}.{name}: {error}"
            else:
                pytest.fail(f"{cls.__name__}.{name} ran on an uninitialised object")
        assert refused, f"{cls.__name__}.{name} never reached the object"


@pytest.mark.parametrize("cls", bound_classes(), ids=lambda cls: cls.__name__)
def test_an_uninitialised_object_passed_as_an_argument_is_refused(cls, made):
    """Every function, constructor and method that takes an object of the class refuses a bare one
    in each argument position (the other arguments real or None)."""
    callables = [(name, getattr(_tsah, name)) for name in module_functions()]
    callables += [(other.__name__, other) for other in bound_classes()]
    for other in bound_classes():
        if other.__name__ in made:
            callables += [(f"{other.__name__}.{name}", getattr(made[other.__name__], name))
                          for name in methods_and_properties(other) if not isinstance(vars(other)[name], property)]
    takers = 0
    for name, function in callables:
        # pybind11's signature lines, e.g. "costs(self: tsah._tsah.Tree, animation: tsah._tsah.Animation, ...)".
        parameter = re.compile(r"\b(?!self\b)\w+: tsah\._tsah\." + cls.__name__ + r"\b")
        signature = (function.__init__ if isinstance(function, type) else function).__doc__ or ""
        if not parameter.search(signature):
            continue
        takers += 1
        refused = False
        for count in range(1, MAX_ARGUMENTS + 1):
            for position in range(count):
                arguments = [None] * count
                arguments[position] = bare(cls)
                try:
                    function(*arguments)
                except tsah.ConfigError as error:
                    if is_not_initialised_error(error, cls):
                        refused = True
                    else:  # a None where an array belongs, looked at after the bare object was accepted
                        assert isinstance(error, tsah.ArgumentTypeError), f"{name}: {error}"
                except TypeError as error:
                    assert "incompatible" in str(error), f"{name}: {error}"
        assert refused, f"{name} takes a {cls.__name__} but never refused a bare one"
    if cls.__name__ in ("Animation", "Tree"):
        assert takers > 0, cls


def test_the_message_names_the_class_and_the_way_out():
    with pytest.raises(tsah.ConfigError) as caught:
        bare(tsah.CpuRuntime).trace(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    assert str(caught.value) == ("tsah.CpuRuntime is not initialised (made by CpuRuntime.__new__ without __init__): "
                                 "call tsah.CpuRuntime(...)")


def test_a_real_object_still_works(made, sample):
    hits = made["CpuRuntime"].trace(np.array([[0, 0, -100]], np.float32), np.array([[0, 0, 1]], np.float32))
    assert hits.shape == (1,)
    assert made["Tree"].node_count > 0 and sample.triangle_count > 0
