"""Lets the examples run straight from the source tree after the README's build command: if
`trellis_mech` is not importable (no PYTHONPATH, no install), the build tree's package
(build/python, or $TRELLIS_BUILD_DIR/python) is put on sys.path."""
import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]

try:
    import trellis_mech  # noqa: F401
except ImportError:
    build = pathlib.Path(os.environ.get("TRELLIS_BUILD_DIR", ROOT / "build"))
    sys.path.insert(0, str(build / "python"))
    try:
        import trellis_mech  # noqa: F401
    except ImportError as error:
        sys.exit(f"{error}\ntrellis_mech is not built for this interpreter ({sys.executable}); "
                 f"build it (cmake --build --preset default) and run the example with the "
                 f"interpreter named in {build / 'python' / 'env.sh'}")
