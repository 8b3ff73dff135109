"""The type stubs (python/tsah/__init__.pyi) against the module, found by introspection: the same
public names, the same public members of each class, the same parameter names of every function
and method, and a docstring for each of them in both."""
import ast
import pathlib
import re

import pytest

import tsah
from tsah import _tsah

STUB = pathlib.Path(__file__).resolve().parents[1] / "tsah" / "__init__.pyi"
CUDA_ONLY = {"DeviceArray", "GpuRuntime", "GpuTwoLevelRuntime"}  # stubbed always; in the module only when cuda_built


@pytest.fixture(scope="module")
def stub():
    return ast.parse(STUB.read_text())


def stub_names(tree):
    """Top-level public names of the stub: classes, functions (overloads once), annotated values."""
    names = {}
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names.setdefault(node.name, []).append(node)
        elif isinstance(node, ast.AnnAssign):
            names.setdefault(node.target.id, []).append(node)
    return {name: nodes for name, nodes in names.items() if not name.startswith("_") or name == "__version__"}


def public_members(cls):
    return {name for name in vars(cls) if not name.startswith("_")}


def stub_members(node):
    return {item.name: item for item in node.body if isinstance(item, ast.FunctionDef) and not item.name.startswith("_")}


def module_parameters(function):
    """Parameter names from pybind11's signature line ('name(a: T, b: T = 1) -> R'); of an overloaded
    function ('name(*args, **kwargs)', then '1. name(...)' per overload) the first overload's, whose
    names the others share."""
    lines = function.__doc__.splitlines()
    signature = next((line[3:] for line in lines if line.startswith("1. ")), lines[0]) \
        if lines[0].endswith("(*args, **kwargs)") else lines[0]
    return [name for name in re.findall(r"(?:\(|, )(\w+): ", signature) if name != "self"]


def stub_parameters(node):
    arguments = node.args
    return [a.arg for a in arguments.posonlyargs + arguments.args + arguments.kwonlyargs if a.arg != "self"]


def module_doc(value):
    """The docstring text beyond pybind11's signature line."""
    doc = value.__doc__ or ""  # a property's own, not its getter's (the signature alone)
    lines = doc.strip().splitlines()
    if lines and re.match(r"^(\w+)?\(.*\) -> ", lines[0]):
        lines = lines[1:]
    return "\n".join(lines).strip()


def test_the_stub_names_every_public_name(stub):
    names = set(stub_names(stub))
    public = set(tsah.__all__)
    assert names - CUDA_ONLY == public - CUDA_ONLY
    assert public <= names
    module_public = {name for name in vars(_tsah) if not name.startswith("_")} | {"__version__"}
    assert module_public == public, "tsah.__all__ and the extension's names differ"


def test_every_class_has_the_stubs_members_and_parameters(stub):
    for name, nodes in stub_names(stub).items():
        if not isinstance(nodes[0], ast.ClassDef) or not hasattr(tsah, name):
            continue
        cls = getattr(tsah, name)
        members = stub_members(nodes[0])
        assert set(members) == public_members(cls), name
        for member, node in members.items():
            value = vars(cls)[member]
            if not isinstance(value, property):
                assert stub_parameters(node) == module_parameters(value), f"{name}.{member}"
        if "__init__" in vars(cls) and "__init__" in {i.name for i in nodes[0].body if isinstance(i, ast.FunctionDef)}:
            init = next(i for i in nodes[0].body if isinstance(i, ast.FunctionDef) and i.name == "__init__")
            assert stub_parameters(init) == module_parameters(vars(cls)["__init__"]), f"{name}.__init__"


def test_every_function_has_the_stubs_parameters(stub):
    for name, nodes in stub_names(stub).items():
        if isinstance(nodes[0], ast.FunctionDef):
            for node in nodes:  # each overload
                assert stub_parameters(node) == module_parameters(getattr(tsah, name)), name


def test_everything_public_has_a_docstring(stub):
    for name, nodes in stub_names(stub).items():
        for node in nodes:
            if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
                assert ast.get_docstring(node), f"stub: {name}"
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef):
                        assert ast.get_docstring(item), f"stub: {name}.{item.name}"
    for name in tsah.__all__:
        value = getattr(tsah, name)
        if name.startswith("_") or not callable(value):
            continue
        assert (value.__doc__ or "").strip() if isinstance(value, type) else module_doc(value), name
        if isinstance(value, type) and not issubclass(value, BaseException):
            for member in public_members(value):
                assert module_doc(vars(value)[member]), f"{name}.{member}"


def test_the_stub_is_installed_with_the_package():
    assert (pathlib.Path(tsah.__file__).parent / "__init__.pyi").is_file()
