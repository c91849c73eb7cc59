"""PEP 517 build backend for trellis_mech, driving the top-level CMake (pyproject.toml names it).

    pip install --no-build-isolation .        # configure + build in a temporary directory
    pip install --no-build-isolation . --config-settings build-dir=build   # reuse a configured build

A wheel holds the package as the build tree lays it out, build/python/trellis_mech/: the extension
_trellis_mech*.so (the trellis libraries linked in statically; SUNDIALS and Ipopt from the system),
__init__.py, _version.py, the type stubs *.pyi and py.typed. The version is CMake's
`project(trellis VERSION ...)`, read here from CMakeLists.txt and written by CMake into _version.py:
one number, one place.

config_settings (pip: --config-settings KEY=VALUE):
    build-dir   a build directory to use: when it holds a CMakeCache.txt it is built, not
                configured again (the interpreter it was configured for must be this one);
                otherwise it is configured there. Default: a new temporary directory.
    cmake.args  extra arguments for the configure step, separated by ';' (e.g.
                -DTRELLIS_BUILD_EXAMPLES=ON to include trellis_mech.hand).
The environment variable TRELLIS_PIP_BUILD_DIR is read when build-dir is not given.

Standard library only: scikit-build-core is not packaged for Debian 12, and a machine without a
package index must still build (hence --no-build-isolation: no build requirements to fetch)."""
import base64
import hashlib
import io
import os
import pathlib
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import zipfile

SOURCE_DIR = pathlib.Path(__file__).resolve().parents[2]
NAME = "trellis_mech"           # import name and normalized distribution name
DIST_NAME = "trellis-mech"
SUMMARY = "Exact linearizations of constrained mechanical systems, TV-LQR and trajectory optimization"


class BuildError(RuntimeError):
    """A build step failed; the message names the step and what to do."""


def project_version(source_dir=SOURCE_DIR):
    """The VERSION of project(trellis ...) in the top-level CMakeLists.txt."""
    text = (pathlib.Path(source_dir) / "CMakeLists.txt").read_text(encoding="utf-8")
    match = re.search(r"project\(\s*trellis\s+VERSION\s+([0-9]+(?:\.[0-9]+){0,3})\b", text)
    if not match:
        raise BuildError(f"{source_dir}/CMakeLists.txt: no 'project(trellis VERSION x.y.z ...)'")
    return match.group(1)


def _setting(config_settings, key):
    value = (config_settings or {}).get(key)
    if isinstance(value, list):  # pip passes a repeated key as a list
        value = ";".join(value)
    return value


def _run(step, command, cwd=None):
    print(f"trellis_build: {step}: {' '.join(map(str, command))}", file=sys.stderr, flush=True)
    done = subprocess.run(list(map(str, command)), cwd=cwd, stdout=sys.stderr)
    if done.returncode != 0:
        raise BuildError(f"{step} failed (exit status {done.returncode}): {' '.join(map(str, command))}")


def _cache_value(build_dir, name):
    cache = pathlib.Path(build_dir) / "CMakeCache.txt"
    for line in cache.read_text(encoding="utf-8", errors="replace").splitlines():
        key, sep, value = line.partition("=")
        if sep and key.split(":")[0] == name:
            return value
    return None


def _build_package(build_dir, config_settings):
    """Configures (unless build_dir is configured already) and builds the target _trellis_mech;
    returns build_dir/python/trellis_mech."""
    build_dir = pathlib.Path(build_dir).resolve()
    if (build_dir / "CMakeCache.txt").exists():
        python = _cache_value(build_dir, "Python3_EXECUTABLE")
        if python and os.path.realpath(python) != os.path.realpath(sys.executable):
            raise BuildError(f"{build_dir} builds trellis_mech for {python}, but pip runs {sys.executable}: "
                             f"run pip with that interpreter, or give another build-dir")
    else:
        args = [f"-DPython3_EXECUTABLE={sys.executable}", "-DCMAKE_BUILD_TYPE=Release",
                "-DTRELLIS_BUILD_TESTS=OFF", "-DTRELLIS_BUILD_BENCHMARKS=OFF", "-DTRELLIS_BUILD_EXAMPLES=OFF"]
        extra = _setting(config_settings, "cmake.args")
        args += [a for a in (extra or "").split(";") if a]
        _run("configure", ["cmake", "-S", SOURCE_DIR, "-B", build_dir, *args])
    jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(min(os.cpu_count() or 1, 2))
    _run("build", ["cmake", "--build", build_dir, "--target", "_trellis_mech", "-j", jobs])
    package = build_dir / "python" / NAME
    if not list(package.glob("_trellis_mech*.so")):
        raise BuildError(f"{package}: no _trellis_mech*.so after the build (is TRELLIS_BUILD_PYTHON "
                         f"ON, and were pybind11-dev, python3-dev, python3-numpy found? see the "
                         f"configure output above)")
    return package


def _wheel_tag():
    impl = sys.implementation.cache_tag.replace("cpython-", "cp")  # cp311
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{impl}-{impl}-{platform}"


def _metadata(version):
    return (f"Metadata-Version: 2.1\nName: {DIST_NAME}\nVersion: {version}\nSummary: {SUMMARY}\n"
            f"License: BSD-3-Clause\nRequires-Python: >=3.8\nRequires-Dist: numpy\n")


def _record_line(arcname, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{arcname},sha256={digest},{len(data)}"


# ---- PEP 517 hooks --------------------------------------------------------------------------------

def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    version = project_version()
    dist_info = pathlib.Path(metadata_directory) / f"{NAME}-{version}.dist-info"
    dist_info.mkdir(parents=True, exist_ok=True)
    (dist_info / "METADATA").write_text(_metadata(version), encoding="utf-8")
    return dist_info.name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    version = project_version()
    build_dir = _setting(config_settings, "build-dir") or os.environ.get("TRELLIS_PIP_BUILD_DIR")
    scratch = None
    if not build_dir:
        scratch = tempfile.mkdtemp(prefix="trellis-wheel-")
        build_dir = scratch
    try:
        package = _build_package(build_dir, config_settings)
        files = sorted(p for p in package.iterdir()
                       if p.is_file() and (p.suffix in (".py", ".pyi") or p.name == "py.typed"
                                           or p.name.startswith("_trellis_mech") and p.suffix == ".so"))
        version_file = package / "_version.py"
        if not version_file.exists() or f'"{version}"' not in version_file.read_text(encoding="utf-8"):
            raise BuildError(f"{version_file}: missing or not version {version} (reconfigure {build_dir})")
        tag = _wheel_tag()
        wheel_name = f"{NAME}-{version}-{tag}.whl"
        dist_info = f"{NAME}-{version}.dist-info"
        entries = [(f"{NAME}/{p.name}", p.read_bytes()) for p in files]
        entries.append((f"{dist_info}/METADATA", _metadata(version).encode()))
        entries.append((f"{dist_info}/WHEEL", (f"Wheel-Version: 1.0\nGenerator: trellis_build\n"
                                               f"Root-Is-Purelib: false\nTag: {tag}\n").encode()))
        licence = (SOURCE_DIR / "LICENSE").read_bytes()
        entries.append((f"{dist_info}/LICENSE", licence))
        record = [_record_line(name, data) for name, data in entries] + [f"{dist_info}/RECORD,,"]
        entries.append((f"{dist_info}/RECORD", ("\n".join(record) + "\n").encode()))
        os.makedirs(wheel_directory, exist_ok=True)
        target = pathlib.Path(wheel_directory) / wheel_name
        with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED) as wheel:
            for name, data in entries:
                info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
                info.compress_type = zipfile.ZIP_DEFLATED
                wheel.writestr(info, data)
        return wheel_name
    finally:
        if scratch:
            shutil.rmtree(scratch, ignore_errors=True)


def build_sdist(sdist_directory, config_settings=None):
    """The tracked source files (git ls-files) or, outside a git checkout, the tree without
    build directories, as trellis_mech-VERSION.tar.gz."""
    version = project_version()
    base = f"{NAME}-{version}"
    listed = subprocess.run(["git", "-C", str(SOURCE_DIR), "ls-files", "-z"], capture_output=True)
    if listed.returncode == 0:
        names = [n for n in listed.stdout.decode().split("\0") if n and (SOURCE_DIR / n).exists()]
    else:
        names = [str(p.relative_to(SOURCE_DIR)) for p in SOURCE_DIR.rglob("*")
                 if p.is_file() and not p.relative_to(SOURCE_DIR).parts[0].startswith(("build", ".git"))]
    os.makedirs(sdist_directory, exist_ok=True)
    target = pathlib.Path(sdist_directory) / f"{base}.tar.gz"
    with tarfile.open(target, "w:gz") as sdist:
        for name in sorted(names):
            sdist.add(SOURCE_DIR / name, arcname=f"{base}/{name}", recursive=False)
        pkg_info = _metadata(version).encode()
        info = tarfile.TarInfo(f"{base}/PKG-INFO")
        info.size = len(pkg_info)
        sdist.addfile(info, io.BytesIO(pkg_info))
    return target.name
