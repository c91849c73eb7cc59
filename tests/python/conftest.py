"""Shared fixtures of the Python tests: where the source tree, its data and the CLI are.

CTest (python/CMakeLists.txt) sets PYTHONPATH to the build tree's package and TRELLIS_SOURCE_DIR,
TRELLIS_CLI; run by hand, the defaults below find them from this file. Everything the tests read
is inside the source tree."""
import os
import pathlib
import subprocess

import pytest

SOURCE_DIR = pathlib.Path(os.environ.get("TRELLIS_SOURCE_DIR",
                                         pathlib.Path(__file__).resolve().parents[2]))
ROBOTS = SOURCE_DIR / "tests" / "data" / "robots"
PAPER_ERRATA = SOURCE_DIR / "docs" / "paper_errata.md"
SCENES = SOURCE_DIR / "examples" / "scenes"
TRAJECTORIES = SOURCE_DIR / "examples" / "trajectories"
PROBLEMS = SOURCE_DIR / "examples" / "problems"


def cli_env():
    """The environment for the C++ command-line tool. Under a sanitizer build CTest preloads the
    sanitizer runtime into the interpreter (LD_PRELOAD, python/CMakeLists.txt); the tool links its
    own runtime (clang: statically), so it must not inherit the preload."""
    env = dict(os.environ)
    env.pop("LD_PRELOAD", None)
    return env


def _cli():
    path = os.environ.get("TRELLIS_CLI") or str(SOURCE_DIR / "build" / "cli" / "trellis")
    return path if os.path.exists(path) else None


@pytest.fixture(scope="session")
def cli():
    """Runs the C++ command-line tool `trellis` and returns its standard output."""
    path = _cli()
    if path is None:
        pytest.skip("the trellis command-line tool is not built")

    def run(*args):
        done = subprocess.run([path, *map(str, args)], capture_output=True, text=True, env=cli_env())
        assert done.returncode == 0, done.stderr
        return done.stdout
    return run


@pytest.fixture(scope="session")
def tm():
    import trellis_mech
    return trellis_mech
