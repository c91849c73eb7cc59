"""trellis_mech optimization bindings: problems from files and built in Python, optimize_trajectory
against `trellis optimize` on the same file, statuses, callbacks and errors."""
import threading

import numpy as np
import pytest

from conftest import PROBLEMS, SCENES


@pytest.mark.parametrize("name", ["cart_pole_swingup", "paper_pendulum_transfer"])
def test_optimize_matches_cli(tm, cli, tmp_path, name):
    path = PROBLEMS / f"{name}.json"
    out = tmp_path / "traj.csv"
    text = cli("optimize", path, "--quiet", "--out", out)
    summary = dict(line.split(": ", 1) for line in text.strip().splitlines())
    problem = tm.load_problem(str(path))
    result = tm.optimize_trajectory(problem)
    assert result.success, result.message
    assert result.status.name.lower() == summary["status"]
    assert result.ipopt_status == summary["ipopt_status"]
    assert result.iterations == int(summary["iterations"])
    assert result.cost == pytest.approx(float(summary["cost"]), rel=1e-9)  # printed with 10 digits
    expected = tm.Trajectory.read_csv(str(out))
    # Same deterministic solve on the same input (CSV: 17 digits).
    np.testing.assert_allclose(result.trajectory.states, expected.states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.trajectory.inputs, expected.inputs, rtol=0, atol=1e-12)
    assert result.constraint_violation < 1e-7


def pendulum_problem(tm):
    """Swing the pendulum from hanging (θ = 0) to θ = 1 rad at rest in 2 s, built in Python."""
    model = tm.load_scene(str(SCENES / "pendulum.json")).model
    p = tm.OptimalControlProblem(model)
    p.method = tm.CollocationMethod.HERMITE_SIMPSON
    p.knots = 21
    p.set_fixed_horizon(2.0)
    p.initial_state = [0.0, 0.0]
    p.final_state = [1.0, 0.0]
    p.R = [[1.0]]
    p.input_lower, p.input_upper = [-20.0], [20.0]
    return p


def test_problem_built_in_python(tm):
    p = pendulum_problem(tm)
    assert p.state_names == ["theta", "dtheta"]
    assert p.initial_fixed == [True, True]
    p.validate()
    result = tm.optimize_trajectory(p, options=tm.OptimizerOptions(tolerance=1e-9))
    assert result.success, result.message
    traj = result.trajectory
    assert traj.states.shape == (21, 2) and traj.inputs.shape == (21, 1)  # time first
    np.testing.assert_allclose(traj.states[0], [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(traj.states[-1], [1.0, 0.0], atol=1e-8)
    # The dynamics were enforced: the nonlinear plant driven open loop by the optimized input
    # ends near the goal (Hermite–Simpson: O(h⁴) error, h = 0.1).
    traj.compute_state_derivatives(p.model)
    sim = tm.simulate_open_loop(p.model, traj, traj.states[0])
    assert sim.ok
    np.testing.assert_allclose(sim.trajectory.states[-1], [1.0, 0.0], atol=0.01)
    assert result.solve_time > 0 and result.dynamics_evaluations > 0


def test_problem_errors(tm, tmp_path):
    p = pendulum_problem(tm)
    p.knots = 1
    with pytest.raises(tm.ProblemError, match="knots") as err:
        p.validate()
    assert isinstance(err.value, ValueError)
    with pytest.raises(tm.ProblemError, match="knots"):
        tm.optimize_trajectory(p)
    p = pendulum_problem(tm)
    p.input_lower = [30.0]
    with pytest.raises(tm.ProblemError, match="input"):
        tm.optimize_trajectory(p)
    bad = tmp_path / "bad.json"
    bad.write_text('{"scene": "nowhere.json", "knots": 11, "horizon": 1.0}')
    with pytest.raises(ValueError, match="nowhere.json"):
        tm.load_problem(str(bad))
    with pytest.raises(ValueError, match="maxIterations"):
        tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(max_iterations=-1))


def test_on_iteration_callback_and_statuses(tm):
    seen = []

    def stop_at_three(info):
        seen.append((info.iteration, info.cost))
        return info.iteration < 3
    result = tm.optimize_trajectory(pendulum_problem(tm),
                                    options=tm.OptimizerOptions(on_iteration=stop_at_three))
    assert result.status == tm.OptimizationStatus.STOPPED and not result.success
    assert [i for i, _ in seen] == [0, 1, 2, 3]

    def raises(info):
        raise KeyError("from the callback")
    result = tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(on_iteration=raises))
    assert not result.success and "callback" in result.message

    result = tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(max_iterations=2))
    assert result.status == tm.OptimizationStatus.ITERATION_LIMIT
    assert result.trajectory.states.shape == (21, 2)  # the last iterate is still returned


def test_optimize_releases_the_gil(tm):
    """Two solves on two threads give the same results as one (and run without the GIL)."""
    problem = tm.load_problem(str(PROBLEMS / "cart_pole_swingup.json"))
    one = tm.optimize_trajectory(problem)
    results = [None, None]
    threads = [threading.Thread(target=lambda i=i: results.__setitem__(i, tm.optimize_trajectory(problem)))
               for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        assert r.iterations == one.iterations
        np.testing.assert_array_equal(r.trajectory.states, one.trajectory.states)
