"""Shared fixtures of the Python tests: the command line (TSAH_CLI), the bundled sample and a runner
that returns the CLI's stdout, its JSON or its one-line error. ctest sets the environment
(python/CMakeLists.txt); run by hand with
  PYTHONPATH=build/release/python TSAH_CLI=build/release/apps/tsah /usr/bin/python3 -m pytest python/tests
"""
import json
import os
import pathlib
import subprocess

import pytest

SOURCE_DIR = pathlib.Path(os.environ.get("TSAH_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
SAMPLE = SOURCE_DIR / "samples" / "explode"


@pytest.fixture(scope="session")
def cli():
    path = os.environ.get("TSAH_CLI")
    if not path or not os.access(path, os.X_OK):
        pytest.skip("TSAH_CLI does not name the tsah program")

    class Cli:
        def run(self, *args):
            return subprocess.run([path, *map(str, args)], capture_output=True, text=True, check=True).stdout

        def json(self, *args):
            return json.loads(self.run(*args, "--json"))

        def error(self, *args):
            """The one-line error of a failing command, without the 'tsah: ' prefix."""
            done = subprocess.run([path, *map(str, args)], capture_output=True, text=True)
            assert done.returncode != 0, f"tsah {args} should have failed"
            lines = done.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("tsah: "), done.stderr
            return lines[0][len("tsah: "):]

    return Cli()


@pytest.fixture(scope="session")
def sample_path():
    return str(SAMPLE)


@pytest.fixture(scope="session")
def sample(sample_path):
    import tsah
    return tsah.load(sample_path)
