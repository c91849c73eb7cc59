"""`trellis gains --hold` on a real robot's URDF with no other file (issue 13), checked against an
independent route: the CLI's holding inputs, the Python binding's linearization there, and the
algebraic Riccati equation (a long horizon makes K(0) converge to the CARE gain)."""
import json

import numpy as np
import pytest

from conftest import ROBOTS

URDF = ROBOTS / "double_pendulum_continuous.urdf"


@pytest.fixture()
def urdf():
    assert URDF.exists(), f"{URDF}: a test robot of the source tree is missing"
    return URDF


def test_hold_gains_converge_to_care(tm, cli, tmp_path, urdf):
    """Upright double pendulum (unstable), Q = 10 I, R = I over 8 s: K(0) is the CARE gain of the
    linearization at the held pose to 1e-6 relative (the backward Riccati converges like
    e^{-2 sigma T}, sigma the closed loop's slowest decay rate, here far below 1e-6)."""
    hold = json.loads(cli("equilibrium", "--hold", "--compact", urdf))
    model = tm.load_scene(str(urdf)).model
    q = np.array([hold["state"]["q"][name] for name in model.config_names])
    u = np.array(hold["u"])
    out = tmp_path / "gains.csv"
    summary = cli("gains", urdf, "--hold", "8", "--Q", "10", "--out", out)
    assert "101 rows of K (2 x 4)" in summary

    data = tm.Data(model)
    status = tm.compute_linearization(model, data, q, np.zeros(model.nq), u)
    assert status.ok
    # The pose is held: the inputs cancel gravity (q'' = 0 to rounding).
    assert np.abs(data.qdd).max() < 1e-9
    care = tm.solve_care(data.A, data.B, 10 * np.eye(4), np.eye(2))
    assert care.status.code == "ok", care.describe()
    gains = tm.GainSchedule.read_csv(str(out))
    assert gains.times[0] == 0.0 and gains.times[-1] == 8.0
    np.testing.assert_allclose(gains.gains[0], care.K, rtol=0, atol=1e-6 * np.abs(care.K).max())
    # Near T the gain is far from the CARE one (S(T) = Qf = Q): the check above can fail.
    assert np.abs(gains.gains[-1] - care.K).max() > 1e-2 * np.abs(care.K).max()


def test_hold_gains_urdf_with_closing_constraint(tm, cli, tmp_path, urdf):
    """A scene that starts from the URDF and adds a frame tree and a distance constraint that holds
    at q = 0: the gains are on the constraint manifold (tangent dimension 2 of 4), and every gain
    row annihilates the constraint's normal direction [A(q) 0] (K = Kr T^T, T spans the tangent)."""
    scene = tmp_path / "tethered.json"
    scene.write_text(json.dumps({
        "urdf": str(urdf),
        "frames": [{"name": "tip", "parent": "link2", "type": "tz", "value": 0.2},
                   {"name": "a1", "type": "tx", "value": 0.0290872},
                   {"name": "a2", "parent": "a1", "type": "ty", "value": 0.1},
                   {"name": "anchor", "parent": "a2", "type": "tz", "value": 0.335}],
        "constraints": [{"name": "tether", "type": "distance", "frame1": "tip", "frame2": "anchor",
                         "distance": 0.1}]}))
    out = tmp_path / "gains.csv"
    summary = cli("gains", scene, "--hold", "3", "--Q", "10", "--out", out)
    assert "tangent dimension 2 of 4" in summary
    model = tm.load_scene(str(scene)).model
    data = tm.Data(model)
    status = tm.compute_linearization(model, data, np.zeros(2), np.zeros(2), np.zeros(model.nu))
    assert status.ok
    assert tm.compute_constraint_tangent_basis(model, data) == 2
    T = data.tangent_basis
    assert T.shape == (4, 2)
    gains = tm.GainSchedule.read_csv(str(out))
    K0 = gains.gains[0]
    assert np.abs(K0).max() > 0.1
    # K = Kr T^T: the part of K outside the span of T^T is zero to rounding.
    projector = T @ np.linalg.pinv(T)
    np.testing.assert_allclose(K0 @ projector, K0, rtol=0, atol=1e-9 * np.abs(K0).max())


def test_hold_refuses_trajectory_and_names_options(cli, tmp_path, urdf):
    import subprocess
    from conftest import _cli, cli_env
    done = subprocess.run([_cli(), "gains", str(urdf), "--hold", "1", "--trajectory", "x.csv",
                           "--out", str(tmp_path / "g.csv")], capture_output=True, text=True,
                          env=cli_env())
    assert done.returncode == 2
    assert "--hold and --trajectory exclude each other" in done.stderr
    done = subprocess.run([_cli(), "gains", str(urdf), "--hold", "-1", "--out", str(tmp_path / "g.csv")],
                          capture_output=True, text=True, env=cli_env())
    assert done.returncode == 2 and "--hold" in done.stderr
    assert not (tmp_path / "g.csv").exists()
