"""The Python examples end to end (examples/python/), each in a fresh interpreter: the same one
that runs the tests (so the same build of trellis_mech)."""
import subprocess
import sys

import pytest

from conftest import SOURCE_DIR

EXAMPLES = SOURCE_DIR / "examples" / "python"


def run(script, *args):
    done = subprocess.run([sys.executable, str(EXAMPLES / script), *map(str, args)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_paper_example():
    out = run("paper_example.py")
    assert "PASS" in out


def test_readme_example():
    """The README's Python block (examples/readme/cart_pole.py), run from the source root as the
    README says: the balancing gain stabilizes the upright cart-pole."""
    done = subprocess.run([sys.executable, str(SOURCE_DIR / "examples" / "readme" / "cart_pole.py")],
                          capture_output=True, text=True, timeout=120, cwd=SOURCE_DIR)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "states: ['x', 'theta', 'dx', 'dtheta']" in done.stdout
    assert "closed loop:" in done.stdout


def test_cart_pole(tmp_path):
    out = run("cart_pole.py", tmp_path)
    assert "optimize: SOLVED" in out
    assert (tmp_path / "cart_pole.png").stat().st_size > 10000
    lines = (tmp_path / "gains.csv").read_text().splitlines()
    assert lines[0].startswith("# trellis gain schedule: m=1 nx=4")
    assert lines[1].startswith("t,K[push|x],")


def test_hand_gains(tmp_path, tm):
    if not hasattr(tm, "hand"):
        pytest.skip("built without the examples")
    out = run("hand_gains.py", tmp_path)
    assert "controllability at t = 0: rank 10 of 10" in out
    assert (tmp_path / "hand_gains.png").exists()
