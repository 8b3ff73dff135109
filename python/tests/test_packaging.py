"""The package as an interpreter without numpy, or with a numpy too new for the pybind11 it was built
with, sees it: one clear ImportError at `import tsah` (not a bare "No module named 'numpy'" at the
first array call, nor arrays with wrong strides)."""
import os
import pathlib
import subprocess
import sys

import tsah


def test_import_without_numpy_names_numpy_and_the_interpreter(tmp_path):
    # A numpy that cannot be imported, first on the path: what an interpreter without numpy gives.
    fake = tmp_path / "numpy"
    fake.mkdir()
    (fake / "__init__.py").write_text("raise ImportError(\"No module named 'numpy'\")\n")
    package_parent = pathlib.Path(tsah.__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(package_parent)]))
    done = subprocess.run([sys.executable, "-c", "import tsah"], capture_output=True, text=True, env=env)
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: tsah needs numpy"), done.stderr
    assert sys.executable in last


def test_import_with_numpy_2_needs_pybind11_2_12(tmp_path):
    from tsah import _build_info
    # A numpy that reports version 2.0.0, first on the path: only the version check reads it.
    fake = tmp_path / "numpy"
    fake.mkdir()
    (fake / "__init__.py").write_text('__version__ = "2.0.0"\n')
    package_parent = pathlib.Path(tsah.__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(package_parent)]))
    done = subprocess.run([sys.executable, "-c", "import tsah"], capture_output=True, text=True, env=env)
    major_minor = tuple(int(part) for part in _build_info.pybind11_version.split(".")[:2])
    if major_minor >= (2, 12):
        assert "does not support numpy" not in done.stderr
    else:
        assert done.returncode != 0
        last = done.stderr.strip().splitlines()[-1]
        assert last.startswith(f"ImportError: tsah was built with pybind11 {_build_info.pybind11_version}, "
                               "which does not support numpy 2.0.0"), done.stderr
        assert sys.executable in last
