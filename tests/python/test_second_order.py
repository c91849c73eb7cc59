"""The exact second derivatives in Python (python/src/bind_second_order.cpp): the six tensors as
NumPy arrays, the contraction as a function, against the CLI and against central differences of
the exact Jacobians."""
import json
import math

import numpy as np
import pytest

from conftest import SCENES

BLOCKS = ["d2qdd_dqdq", "d2qdd_dqddq", "d2qdd_ddqddq", "d2qdd_dudq", "d2qdd_duddq", "d2qdd_dudu"]


def test_pendulum_closed_form(tm):
    """θ̈ = −g sin θ − 0.1 θ̇ + u: the only nonzero second derivative is ∂²θ̈/∂θ² = g sin θ."""
    scene = tm.load_scene(str(SCENES / "pendulum.json"))
    data = tm.Data(scene.model)
    out = tm.compute_second_order(scene.model, data, [0.3], [0.5], [0.2])
    assert out["status"].ok
    assert out["d2qdd_dqdq"].shape == (1, 1, 1)
    assert out["d2qdd_dqdq"][0, 0, 0] == pytest.approx(9.81 * math.sin(0.3), rel=1e-13)
    for key in BLOCKS[1:]:
        assert np.abs(out[key]).max() <= 1e-13, key


@pytest.mark.parametrize("name", ["cart_pole", "paper_pendulum", "all_elements_3d"])
def test_tensors_match_cli_and_differences(tm, cli, name):
    path = SCENES / f"{name}.json"
    ref = json.loads(cli("linearize", "--second-order", "--compact", path))
    scene = tm.load_scene(str(path))
    model = scene.model
    n, m, nc = model.nq, model.nu, model.nc
    data = tm.Data(model)
    out = tm.compute_second_order(model, data, scene.q, scene.dq, scene.u)
    assert out["status"].ok
    shapes = {"d2qdd_dqdq": (n, n, n), "d2qdd_dqddq": (n, n, n), "d2qdd_ddqddq": (n, n, n),
              "d2qdd_dudq": (n, m, n), "d2qdd_duddq": (n, m, n), "d2qdd_dudu": (n, m, m)}
    for key, shape in shapes.items():
        assert out[key].shape == shape, key
        expected = np.array(ref[key], dtype=float).reshape(shape)
        scale = max(1.0, np.abs(expected).max(initial=0.0))
        # The same C++ computation; only the 17-digit decimal round trip separates them.
        assert np.abs(out[key] - expected).max(initial=0.0) <= 1e-14 * scale, key
    N = 2 * n + m
    assert out["d2qdd_dz2"].shape == (n, N, N) and out["d2lambda_dz2"].shape == (nc, N, N)
    # Central differences of the exact Jacobians (h = eps^(1/3) max(1, |z|), error ~1e-9 of the
    # column; 1e-6 leaves a margin) along every z direction.
    z = np.concatenate([scene.q, scene.dq, scene.u])
    h_rel = np.finfo(float).eps ** (1.0 / 3.0)
    for a in range(N):
        h = h_rel * max(1.0, abs(z[a]))
        jac = []
        for s in (1.0, -1.0):
            zz = z.copy()
            zz[a] += s * h
            lin = tm.linearize(model, zz[:n], zz[n:2 * n], zz[2 * n:])
            jac.append(np.hstack([lin.A[n:, :], lin.B[n:, :]]))
        d = (jac[0] - jac[1]) / ((z[a] + h) - (z[a] - h))
        got = out["d2qdd_dz2"][:, :, a]
        scale = np.maximum(1.0, np.abs(d).max(axis=1, keepdims=True))
        assert (np.abs(got - d) / scale).max() <= 1e-6, a


def test_contraction_is_a_function(tm):
    scene = tm.load_scene(str(SCENES / "all_elements_3d.json"))
    model = scene.model
    data = tm.Data(model)
    out = tm.compute_second_order(model, data, scene.q, scene.dq, scene.u)
    h = tm.second_order_contraction(model, scene.q, scene.dq, scene.u)
    rng = np.random.default_rng(30)
    w = rng.uniform(-1, 1, model.nq)
    rho = rng.uniform(-1, 1, model.nc)
    H = h(w, rho)
    assert h.status.ok
    expected = np.tensordot(w, out["d2qdd_dz2"], axes=1) + np.tensordot(rho, out["d2lambda_dz2"], axes=1)
    assert np.abs(H - expected).max() <= 1e-10 * max(1.0, np.abs(expected).max())
    np.testing.assert_allclose(h(w), np.tensordot(w, out["d2qdd_dz2"], axes=1), rtol=0, atol=1e-10 * max(1.0, np.abs(expected).max()))
    with pytest.raises(ValueError, match="w: expected"):
        h(np.zeros(model.nq + 1))
