"""The Python package (issue 23 part 5): `pip install --no-build-isolation .` through the in-tree
PEP 517 backend (python/build_backend/trellis_build.py), installed into a temporary target from
the existing build directory (TRELLIS_BUILD_DIR: built, not configured again), then imported by a
fresh interpreter that sees only that target; and the backend's own rules."""
import importlib.util
import os
import pathlib
import re
import subprocess
import sys
import zipfile

import pytest

from conftest import SOURCE_DIR

BACKEND = SOURCE_DIR / "python" / "build_backend" / "trellis_build.py"


def backend():
    spec = importlib.util.spec_from_file_location("trellis_build", BACKEND)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cmake_version():
    text = (SOURCE_DIR / "CMakeLists.txt").read_text(encoding="utf-8")
    return re.search(r"project\(trellis VERSION ([0-9.]+)", text).group(1)


def build_dir():
    path = os.environ.get("TRELLIS_BUILD_DIR")
    if not path:
        pytest.skip("TRELLIS_BUILD_DIR is not set (CTest sets it): no build to install from")
    return pathlib.Path(path)


def test_pip_install_into_a_target_and_import(tmp_path):
    build = build_dir()
    target = tmp_path / "site"
    # pip and the CMake it runs are not sanitized programs: no sanitizer preload for them (an ASan
    # build's CTest sets LD_PRELOAD for the interpreter); the import below keeps it.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "LD_PRELOAD")}
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index",
         "--disable-pip-version-check", "--target", str(target),
         "--config-settings", f"build-dir={build}", str(SOURCE_DIR)],
        capture_output=True, text=True, timeout=900, env=env)
    assert done.returncode == 0, f"pip failed:\n{done.stdout}\n{done.stderr}"
    version = cmake_version()
    assert (target / f"trellis_mech-{version}.dist-info" / "METADATA").exists()
    package = target / "trellis_mech"
    assert list(package.glob("_trellis_mech*.so")) and (package / "py.typed").exists()
    assert sorted(p.name for p in package.glob("*.pyi")), "the type stubs are not installed"
    probe = ("import importlib.metadata as md, trellis_mech as tm; "
             "m = tm.load_scene(r'%s').model; "
             "print(tm.__file__); print(tm.__version__, md.version('trellis-mech')); "
             "print(tm.linearize(m, [0.3], [0.0], [0.0]).A[1, 0])" % (SOURCE_DIR / "examples/scenes/pendulum.json"))
    env["PYTHONPATH"] = str(target)
    if "LD_PRELOAD" in os.environ:
        env["LD_PRELOAD"] = os.environ["LD_PRELOAD"]
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    where, versions, a10 = out.stdout.splitlines()
    assert pathlib.Path(where).resolve().is_relative_to(target.resolve())  # not the build tree
    assert versions.split() == [version, version]
    assert float(a10) == pytest.approx(-9.81 * 0.955336489125606, rel=1e-12)  # -g cos θ / l


def test_version_is_cmakes_project_version():
    assert backend().project_version(SOURCE_DIR) == cmake_version()
    import trellis_mech
    assert trellis_mech.__version__ == cmake_version()
    # No second literal: the package's sources do not state a version.
    for path in (SOURCE_DIR / "python" / "trellis_mech").glob("*.py"):
        assert not re.search(r"__version__\s*=\s*['\"]", path.read_text(encoding="utf-8")), path


def test_backend_refuses_a_build_for_another_interpreter(tmp_path):
    (tmp_path / "CMakeCache.txt").write_text("Python3_EXECUTABLE:FILEPATH=/opt/other/python3.99\n")
    b = backend()
    with pytest.raises(b.BuildError, match=r"/opt/other/python3\.99.*run pip with that interpreter"):
        b.build_wheel(str(tmp_path / "wheels"), {"build-dir": str(tmp_path)})
    assert not (tmp_path / "wheels").exists()


def test_backend_metadata(tmp_path):
    b = backend()
    name = b.prepare_metadata_for_build_wheel(str(tmp_path))
    version = cmake_version()
    assert name == f"trellis_mech-{version}.dist-info"
    metadata = (tmp_path / name / "METADATA").read_text()
    assert f"Name: trellis-mech\nVersion: {version}\n" in metadata
    assert "Requires-Dist: numpy" in metadata
    assert b.get_requires_for_build_wheel() == [] and b.get_requires_for_build_sdist() == []


def test_wheel_contents_and_record(tmp_path, monkeypatch):
    """A wheel from the existing build: every file listed in RECORD with its hash, the package
    layout of the build tree, and the platform tag of this interpreter."""
    build = build_dir()
    monkeypatch.delenv("LD_PRELOAD", raising=False)  # for the CMake the backend runs (see above)
    b = backend()
    name = b.build_wheel(str(tmp_path), {"build-dir": str(build)})
    tag = sys.implementation.cache_tag.replace("cpython-", "cp")
    assert name.startswith(f"trellis_mech-{cmake_version()}-{tag}-{tag}-")
    with zipfile.ZipFile(tmp_path / name) as wheel:
        names = set(wheel.namelist())
        record = wheel.read(f"trellis_mech-{cmake_version()}.dist-info/RECORD").decode().splitlines()
    listed = {line.split(",")[0] for line in record}
    assert listed == names
    assert {"trellis_mech/__init__.py", "trellis_mech/_version.py", "trellis_mech/py.typed"} <= names
