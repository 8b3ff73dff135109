"""The package as an interpreter without numpy sees it: one clear ImportError at `import tsah`
(not a bare "No module named 'numpy'" at the first array call)."""
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
