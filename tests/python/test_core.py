"""trellis_mech core bindings: models, builder, Data, dynamics and linearization, NumPy handling,
errors — each checked against the C++ CLI on the same input, a closed form, or the verified table of
docs/paper_errata.md."""
import json
import math
import re
import tracemalloc

import numpy as np
import pytest

from conftest import PAPER_ERRATA, SCENES

SCENE_NAMES = ["pendulum", "cart_pole", "acrobot", "paper_pendulum", "all_elements_3d", "hand"]


def test_model_info(tm):
    scene = tm.load_scene(str(SCENES / "pendulum.json"))
    model = scene.model
    assert (model.nq, model.nx, model.nu, model.nc) == (1, 2, 1, 0)
    assert model.name == "pendulum"
    assert model.config_names == ["theta"]
    assert model.input_names == ["torque"]
    assert model.state_names == ["theta", "dtheta"]
    assert {"pivot", "bob"} <= set(model.frame_names)
    assert model.config_index("theta") == 0
    with pytest.raises(KeyError, match="nope"):
        model.config_index("nope")
    np.testing.assert_array_equal(model.gravity, [0.0, -9.81, 0.0])
    assert scene.q.shape == (1,) and scene.x.shape == (2,)


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_linearization_matches_cli(tm, cli, name):
    """The binding against `trellis linearize` (17 significant digits) at each scene's state."""
    path = SCENES / f"{name}.json"
    ref = json.loads(cli("linearize", "--compact", path))
    scene = tm.load_scene(str(path))
    lin = tm.linearize(scene.model, scene.q, scene.dq, scene.u)
    assert lin.status.ok
    assert scene.model.config_names == ref["configs"]
    for key, value in [("A", lin.A), ("B", lin.B), ("M", lin.M), ("qdd", lin.qdd),
                       ("lambda", lin.lambda_)]:
        expected = np.array(ref[key], dtype=float).reshape(value.shape)
        scale = max(1.0, np.abs(expected).max(initial=0.0))
        # Same C++ code and inputs; only the 17-digit decimal round trip separates them.
        assert np.abs(value - expected).max(initial=0.0) <= 1e-14 * scale, key


def test_pendulum_closed_form(tm):
    """θ̈ = −(g/l) sin θ − c θ̇ + u/(m l²), m = l = 1, g = 9.81, c = 0.1 (the scene's description)."""
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    theta, dtheta, u = 0.3, 0.2, 0.5
    lin = tm.linearize(model, [theta], [dtheta], [u])
    assert lin.qdd[0] == pytest.approx(-9.81 * math.sin(theta) - 0.1 * dtheta + u, rel=1e-13)
    np.testing.assert_allclose(lin.A, [[0, 1], [-9.81 * math.cos(theta), -0.1]], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(lin.B, [[0], [1]], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(lin.M, [[1.0]], rtol=1e-14)


def errata_tables():
    """The verified Sec. IV linearization of docs/paper_errata.md: {u0: 2x5 table}."""
    text = PAPER_ERRATA.read_text(encoding="utf-8")
    number = lambda s: float(s.replace("−", "-"))  # noqa: E731  (the page uses U+2212)
    tables = {}
    for line in text.splitlines():
        m = re.match(r"\s*\|\s*([0-9.]+)\s*\|\s*θ̈[₁₂]\s*\|(.*)\|\s*$", line)
        if m:
            tables.setdefault(float(m.group(1)), []).append([number(v) for v in m.group(2).split("|")])
    assert sorted(tables) == [0.0, 2.0], f"{PAPER_ERRATA}: the verified table has changed"
    assert all(len(rows) == 2 and all(len(r) == 5 for r in rows) for rows in tables.values())
    return {u0: np.array(rows) for u0, rows in tables.items()}


@pytest.mark.parametrize("u0", [0.0, 2.0])
def test_paper_example_errata(tm, u0):
    model = tm.load_scene(str(SCENES / "paper_pendulum.json")).model
    data = tm.Data(model)
    status = tm.compute_linearization(model, data, [0.5246, 1.0472], [1.0, -2.00116], [u0])
    assert status.ok
    table = np.hstack([data.dqdd_dq, data.dqdd_ddq, data.dqdd_du])
    # docs/paper_errata.md prints 7 decimals.
    np.testing.assert_allclose(table, errata_tables()[u0], rtol=0, atol=1e-6)


def pendulum_builder(tm, mass=1.0):
    b = tm.ModelBuilder("pendulum")
    b.add_frame("pivot", "world", tm.Transform.rz("theta"))
    b.add_frame("bob", "pivot", tm.Transform.ty(-1.0), tm.Mass(mass))
    b.add_gravity([0.0, -9.81, 0.0])
    b.add_config_force("theta", "torque")
    b.add_damping(0.1)
    return b


def test_builder_matches_scene(tm):
    built = pendulum_builder(tm).finalize()
    loaded = tm.load_scene(str(SCENES / "pendulum.json")).model
    for q in ([0.0], [0.7], [-2.0]):
        a = tm.linearize(built, q, [0.3], [0.2])
        b = tm.linearize(loaded, q, [0.3], [0.2])
        np.testing.assert_array_equal(a.A, b.A)
        np.testing.assert_array_equal(a.B, b.B)


def test_builder_errors_carry_the_message(tm):
    b = tm.ModelBuilder("bad")
    b.add_frame("pivot", "world", tm.Transform.rz("theta"))
    with pytest.raises(tm.ModelError, match=r"bob.*-1") as err:
        b.add_frame("bob", "pivot", tm.Transform.ty(-1.0), tm.Mass(-1.0))
    assert isinstance(err.value, ValueError)
    with pytest.raises(tm.ModelError, match="nowhere"):
        b.add_frame("x", "nowhere", tm.Transform.tx(1.0))
    with pytest.raises(tm.ModelError, match="field 'frame2': unknown frame 'missing_frame'"):
        b.add_linear_spring("pivot", "missing_frame", 1.0, 0.0)
    b.add_config_spring("no_such_config", 1.0, 0.0)  # names of configurations: checked by finalize
    with pytest.raises(tm.ModelError, match="no_such_config"):
        b.finalize()


def test_scene_errors(tm, tmp_path):
    with pytest.raises(tm.ModelError, match="no_such_file.json"):
        tm.load_scene(str(tmp_path / "no_such_file.json"))
    with pytest.raises(tm.ModelError, match="my.json"):
        tm.parse_scene('{"frames": [{"name": "a", "type": "rq"}]}', "my.json")


def test_input_arrays_any_order_dtype_and_stride(tm):
    """Inputs: contiguous float64 read in place; other dtypes, orders, slices and lists copied."""
    model = tm.load_scene(str(SCENES / "acrobot.json")).model
    data = tm.Data(model)
    q, dq = np.array([0.25, -0.375]), np.array([0.125, 0.5])  # exact in float32 too
    u = np.zeros(model.nu)
    tm.compute_linearization(model, data, q, dq, u)
    A0 = data.A
    big = np.zeros((2, 4))
    big[0, ::2] = q
    variants = [
        (q.tolist(), dq.tolist()),                                   # lists
        (q.astype(np.float32), dq),                                  # float32: converted (copied)
        (big[0, ::2], dq),                                           # non-contiguous slice
        (np.asfortranarray(q), np.ascontiguousarray(dq)),            # both orders (1-D: same)
        (np.array([[0.25], [-0.375]])[:, 0], dq),                    # a column of a 2-D array
    ]
    for qv, dqv in variants:
        tm.compute_linearization(model, data, qv, dqv, u)
        np.testing.assert_array_equal(data.A, A0)
    ints = tm.linearize(model, [0, 1], [0, 0], u)                    # ints convert to float
    floats = tm.linearize(model, [0.0, 1.0], [0.0, 0.0], u)
    np.testing.assert_array_equal(ints.A, floats.A)


def test_out_arrays(tm):
    """A=, B= write into caller arrays of any memory order; wrong dtype/shape/read-only raise."""
    model = tm.load_scene(str(SCENES / "cart_pole.json")).model
    data = tm.Data(model)
    q, dq, u = [0.1, 0.5], [0.2, -0.3], [1.5]
    tm.compute_linearization(model, data, q, dq, u)
    A_ref, B_ref = data.A, data.B
    for order in "CF":
        A = np.empty((4, 4), order=order)
        B = np.empty((4, 1), order=order)
        status = tm.compute_linearization(model, data, q, dq, u, A=A, B=B)
        assert status.ok
        np.testing.assert_array_equal(A, A_ref)
        np.testing.assert_array_equal(B, B_ref)
    big = np.full((8, 8), 7.0)
    tm.compute_linearization(model, data, q, dq, u, A=big[::2, 1::2])  # strided view
    np.testing.assert_array_equal(big[::2, 1::2], A_ref)
    assert (big[1::2, :] == 7.0).all()  # nothing written outside the view
    qdd, lam = np.empty(2), np.empty(0)
    tm.compute_dynamics(model, data, q, dq, u, qdd=qdd, lambda_=lam)
    np.testing.assert_array_equal(qdd, data.qdd)

    with pytest.raises(ValueError, match="out A: must be a float64"):
        tm.compute_linearization(model, data, q, dq, u, A=np.empty((4, 4), dtype=np.float32))
    with pytest.raises(ValueError, match=r"out A: expected shape \(4, 4\), got \(4, 3\)"):
        tm.compute_linearization(model, data, q, dq, u, A=np.empty((4, 3)))
    ro = np.empty((4, 1))
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="out B: is read-only"):
        tm.compute_linearization(model, data, q, dq, u, B=ro)


def test_size_and_workspace_errors(tm):
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    data = tm.Data(model)
    with pytest.raises(ValueError, match=r"q: expected 1 entries \(model.nq\), got 2"):
        tm.compute_linearization(model, data, [0.0, 0.0], [0.0], [0.0])
    with pytest.raises(ValueError, match=r"u: expected 1 entries \(model.nu\), got 0"):
        tm.compute_dynamics(model, data, [0.0], [0.0], [])
    other = tm.load_scene(str(SCENES / "pendulum.json")).model
    with pytest.raises(ValueError, match="another model"):
        tm.compute_dynamics(other, data, [0.0], [0.0], [0.0])


def test_numerical_failure_is_a_status(tm):
    """A joint that moves no mass: M is singular — a status, not an exception."""
    b = tm.ModelBuilder("massless")
    b.add_frame("slider", "world", tm.Transform.tx("x"))
    b.add_config_force("x", "push")
    model = b.finalize()
    lin = tm.linearize(model, [0.0], [0.0], [1.0])
    assert not lin.status.ok
    assert lin.status.code == "singular_mass_matrix"
    assert lin.status.describe().startswith("singular_mass_matrix: ")
    assert lin.status.message


def test_tangent_basis(tm):
    """Paper pendulum at a consistent state: d = 4 − 2, T orthonormal, T^T Φ_x^T = 0, Ar = TᵀAT."""
    model = tm.load_scene(str(SCENES / "paper_pendulum.json")).model
    data = tm.Data(model)
    q = np.array([math.pi / 6, math.pi / 3])
    tm.compute_constraints(model, data, q, [0.0, 0.0])
    a = data.constraint_jacobian[0]
    dq = np.array([1.0, -a[0] / a[1]])
    lin = tm.linearize(model, q, dq, [0.0], data=data, tangent=True)
    T = lin.tangent_basis
    assert T.shape == (4, 2)
    np.testing.assert_allclose(T.T @ T, np.eye(2), atol=1e-13)
    np.testing.assert_allclose(lin.reduced_A, T.T @ lin.A @ T, atol=1e-12)
    np.testing.assert_allclose(lin.reduced_B, T.T @ lin.B, atol=1e-13)
    # T is tangent: the position rows of δx satisfy A(q) δq = 0.
    np.testing.assert_allclose(a @ T[:2], 0.0, atol=1e-12)


def test_energy_and_kinematics(tm):
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    data = tm.Data(model)
    e = tm.compute_energy(model, data, [0.4], [2.0])
    assert e.kinetic == pytest.approx(0.5 * 2.0 ** 2, rel=1e-14)
    tm.compute_kinematics(model, data, [0.4], [2.0])
    bob = data.frame_poses[model.frame_index("bob")]
    np.testing.assert_allclose(bob[:2, 3], [math.sin(0.4), -math.cos(0.4)], atol=1e-14)
    assert e.potential == pytest.approx(-np.dot(model.gravity, bob[:3, 3]), rel=1e-14)  # V = −m g·p
    assert data.frame_velocities.shape == (model.nframes, 6)


def test_reused_data_does_not_grow_memory(tm):
    """The out= hot loop allocates nothing that survives a call (Python-side allocations tracked)."""
    model = tm.load_scene(str(SCENES / "hand.json")).model
    scene = tm.load_scene(str(SCENES / "hand.json"))
    data = tm.Data(model)
    A, B = np.empty((model.nx, model.nx)), np.empty((model.nx, model.nu))
    q, dq, u = scene.q, scene.dq, scene.u
    for _ in range(10):
        tm.compute_linearization(model, data, q, dq, u, A=A, B=B)
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for _ in range(200):
        tm.compute_linearization(model, data, q, dq, u, A=A, B=B)
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    growth = sum(s.size_diff for s in after.compare_to(before, "filename"))
    assert growth < 4096, growth


def test_linearize_raises_on_a_non_finite_state(tm):
    """A NaN or infinite q, dq or u is bad input: the convenience functions raise ValueError naming
    the entry (they returned a failed status beside a wrong A before)."""
    model = tm.load_scene(str(SCENES / "paper_pendulum.json")).model
    q, dq = [math.pi / 6, math.pi / 3], [0.0, 0.0]
    with pytest.raises(ValueError, match=r"q\[1\] \(%s\) = nan is not finite" % model.config_names[1]):
        tm.linearize(model, [q[0], float("nan")], dq, [0.0])
    with pytest.raises(ValueError, match=r"dq\[0\] .* = inf is not finite"):
        tm.linearize(model, q, [float("inf"), 0.0], [0.0])
    with pytest.raises(ValueError, match=r"u\[0\] .* = -inf is not finite"):
        tm.dynamics(model, q, dq, [-float("inf")])
    assert tm.linearize(model, q, dq, [0.0]).status.ok


def test_scene_carries_urdf_limits_and_warnings(tm, tmp_path):
    # A URDF with Coulomb friction read through a scene overlay that drops it: the scene says so
    # (one warning naming the value) and carries the <limit>s per configuration.
    urdf = (
        '<robot name="arm"><link name="base"/>'
        '<link name="upper"><inertial><mass value="1"/>'
        '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>'
        '<joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>'
        '<axis xyz="0 1 0"/><limit lower="-1" upper="1.5" effort="5" velocity="3"/>'
        '<dynamics friction="0.3"/></joint></robot>')
    (tmp_path / "arm.urdf").write_text(urdf)
    with pytest.raises(ValueError, match="friction"):
        tm.load_scene(str(tmp_path / "arm.urdf"))
    overlay = tmp_path / "arm.json"
    overlay.write_text(json.dumps({"urdf": "arm.urdf", "urdf_options": {"ignore_friction": True}}))
    scene = tm.load_scene(str(overlay))
    assert len(scene.warnings) == 1 and "0.3" in scene.warnings[0]
    np.testing.assert_array_equal(scene.lower_limit, [-1.0])
    np.testing.assert_array_equal(scene.upper_limit, [1.5])
    np.testing.assert_array_equal(scene.effort_limit, [5.0])
    plain = tm.load_scene(str(SCENES / "pendulum.json"))
    assert plain.warnings == [] and plain.lower_limit.shape == (0,)
