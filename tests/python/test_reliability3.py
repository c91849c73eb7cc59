"""Issue 24 (reliability, third round), the Python module: complex arrays refused, Ctrl-C in a
policy or an iteration callback propagates, Data(None) is a TypeError (not a crash), file errors
are OSError, a zero-order hold that overflows raises, and solve_tvlqr bounds its grids."""
import numpy as np
import pytest

from conftest import SCENES, TRAJECTORIES
from test_optimization import pendulum_problem


def test_complex_vectors_are_refused_not_truncated(tm):
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    data = tm.Data(model)
    with pytest.raises(TypeError, match="complex array"):
        tm.compute_dynamics(model, data, np.array([0.1 + 0.5j]), [0.0], [0.0])
    # The real array of the same values still works (read in place).
    tm.compute_dynamics(model, data, np.array([0.1]), [0.0], [0.0])


def test_data_of_none_is_a_type_error(tm):
    with pytest.raises(TypeError):
        tm.Data(None)
    with pytest.raises(TypeError):
        tm.OptimalControlProblem(None)


def test_keyboard_interrupt_in_a_policy_propagates(tm):
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    calls = []

    def policy(t, x):
        calls.append(t)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return [0.0]
    with pytest.raises(KeyboardInterrupt):
        tm.simulate(model, [0.1, 0.0], 0.0, 1.0, policy, options=tm.SimulationOptions(output_step=0.1))
    assert len(calls) == 5  # the simulation stopped at the interrupt


def test_keyboard_interrupt_in_on_iteration_propagates(tm):
    seen = []

    def on_iteration(info):
        seen.append(info.iteration)
        if len(seen) == 2:
            raise KeyboardInterrupt
        return True
    with pytest.raises(KeyboardInterrupt):
        tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(on_iteration=on_iteration))
    assert len(seen) == 2


def test_file_errors_are_oserror(tm, tmp_path):
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    traj = tm.Trajectory(model.config_names, model.input_names, [0.0, 1.0], np.zeros((2, 2)), np.zeros((2, 1)))
    with pytest.raises(OSError, match="not accessible"):
        traj.write_csv(str(tmp_path / "missing" / "t.csv"))
    ro = tmp_path / "ro.csv"
    ro.write_text("keep")
    ro.chmod(0o444)
    with pytest.raises(OSError, match="read-only"):
        traj.write_csv(str(ro))
    assert ro.read_text() == "keep"


def test_zero_order_hold_overflow_raises(tm):
    with pytest.raises(tm.NumericalError, match="not finite"):
        tm.discretize_zero_order_hold(np.array([[1.0]]), np.array([[1.0]]), 1e6)
    Ad, Bd = tm.discretize_zero_order_hold(np.array([[1.0]]), np.array([[1.0]]), 1.0)
    assert np.isfinite(Ad).all() and np.isfinite(Bd).all()


def test_solve_tvlqr_bounds_its_grids(tm):
    scene = tm.load_scene(str(SCENES / "cart_pole.json"))
    ref = tm.Trajectory.read_csv(str(TRAJECTORIES / "cart_pole_upright.csv"))
    with pytest.raises(ValueError, match="sample_rate .* the limit is 1000000"):
        tm.solve_tvlqr(scene.model, ref, Q=1.0, R=1.0, options=tm.TvlqrOptions(sample_rate=1e12))
    with pytest.raises(ValueError, match="output_step .* the limit is 1000000"):
        tm.solve_tvlqr(scene.model, ref, Q=1.0, R=1.0, options=tm.TvlqrOptions(output_step=1e-12))
