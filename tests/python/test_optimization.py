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
    assert result.ok, result.message
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
    assert result.ok, result.message
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
    options = tm.OptimizerOptions(refinement_band=0, unresolved_defect=0.2)
    assert (options.refinement_band, options.unresolved_defect) == (0, 0.2)
    assert tm.OptimizerOptions().refinement_band == 3
    assert tm.OptimizerOptions(refinement_grading=1.5).refinement_grading == 1.5
    assert tm.OptimizerOptions().refinement_grading == 0.0
    with pytest.raises(ValueError, match="refinementGrading"):
        tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(refinement_grading=1.0))
    with pytest.raises(ValueError, match="refinementBand = -1"):
        tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(refinement_band=-1))


def test_on_iteration_callback_and_statuses(tm):
    seen = []

    def stop_at_three(info):
        seen.append((info.iteration, info.cost))
        return info.iteration < 3
    result = tm.optimize_trajectory(pendulum_problem(tm),
                                    options=tm.OptimizerOptions(on_iteration=stop_at_three))
    assert result.status == tm.OptimizationCode.STOPPED and not result.ok
    assert [i for i, _ in seen] == [0, 1, 2, 3]

    def raises(info):
        raise KeyError("from the callback")
    result = tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(on_iteration=raises))
    assert not result.ok and "callback" in result.message

    result = tm.optimize_trajectory(pendulum_problem(tm), options=tm.OptimizerOptions(max_iterations=2))
    assert result.status == tm.OptimizationCode.ITERATION_LIMIT
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


def test_hessian_modes_and_reports(tm):
    """The exact Hessian (default) and L-BFGS reach the same optimum, the exact one in fewer
    iterations; the result's describe()/json() are the library's reports."""
    import json

    problem = tm.load_problem(str(PROBLEMS / "cart_pole_swingup.json"))
    assert problem.hessian == tm.HessianMode.EXACT
    exact = tm.optimize_trajectory(problem)
    lbfgs = tm.optimize_trajectory(problem, options=tm.OptimizerOptions(hessian=tm.HessianMode.LBFGS))
    assert exact.ok and lbfgs.ok, (exact.describe(), lbfgs.describe())
    assert exact.hessian == tm.HessianMode.EXACT and lbfgs.hessian == tm.HessianMode.LBFGS
    assert exact.iterations < lbfgs.iterations
    assert exact.cost == pytest.approx(lbfgs.cost, rel=1e-8)
    report = json.loads(exact.json())
    assert list(report)[:5] == ["status", "ok", "message", "t", "index"]
    assert report["status"] == "solved" and report["ok"] and report["hessian"] == "exact"
    assert report["rounds"][0]["hessian"] == "exact"
    assert exact.describe().startswith("solved (Ipopt: Solve_Succeeded")
    assert exact.second_order_evaluations > 0 and lbfgs.second_order_evaluations == 0


def test_problem_file_hessian_key(tm):
    text = (PROBLEMS / "cart_pole_swingup.json").read_text()
    base = str(PROBLEMS)
    lbfgs = tm.parse_problem(text.replace('"knots": 31', '"knots": 31, "hessian": "lbfgs"'), "p.json", base)
    assert lbfgs.hessian == tm.HessianMode.LBFGS
    with pytest.raises(tm.ProblemError, match="p.json: hessian 'newton' is not one of exact, lbfgs"):
        tm.parse_problem(text.replace('"knots": 31', '"knots": 31, "hessian": "newton"'), "p.json", base)


def test_constraint_force_bounds(tm):
    problem = tm.load_problem(str(PROBLEMS / "swingups" / "paper_pendulum_force_bound_transfer.json"))
    np.testing.assert_array_equal(problem.force_lower, [-5.5])
    np.testing.assert_array_equal(problem.force_upper, [5.5])
    result = tm.optimize_trajectory(problem)
    assert result.ok, result.describe()
    problem.force_upper = np.array([np.inf])
    assert np.isinf(problem.force_upper[0])


def test_acceleration_weights(tm):
    # OptimalControlProblem::accelerationWeights: implicit form only, one weight per coordinate;
    # both solves succeed, and the weighted optimum costs more (its cost includes the term).
    p = tm.load_problem(str(PROBLEMS / "cart_pole_swingup.json"))
    assert p.acceleration_weights.shape == (0,)
    p.acceleration_weights = np.full(p.nq, 0.1)
    with pytest.raises(tm.ProblemError, match="needs dynamics = implicit"):
        p.validate()
    p.dynamics = tm.DynamicsForm.IMPLICIT
    p.acceleration_weights = np.full(p.nq + 1, 0.1)
    with pytest.raises(tm.ProblemError, match="accelerationWeights has"):
        p.validate()
    p.acceleration_weights = np.full(p.nq, 0.1)
    p.validate()
    plain = tm.load_problem(str(PROBLEMS / "cart_pole_swingup.json"))
    plain.dynamics = tm.DynamicsForm.IMPLICIT
    a, b = tm.optimize_trajectory(plain), tm.optimize_trajectory(p)
    assert a.ok, a.message
    assert b.ok, b.message
    assert b.cost > a.cost


def test_ordering_and_threads(tm):
    # OptimizerOptions.ordering (MUMPS's fill-reducing ordering) and threads (the implicit form's
    # Hessian blocks): every choice reaches the same optimum; threads give the same iterates.
    p = tm.load_problem(str(PROBLEMS / "cart_pole_swingup.json"))
    p.dynamics = tm.DynamicsForm.IMPLICIT
    base = tm.optimize_trajectory(p, options=tm.OptimizerOptions(max_refinements=0))
    assert base.ok, base.message
    assert tm.OptimizerOptions().ordering == tm.MumpsOrdering.AUTO
    assert tm.OptimizerOptions().threads == 1
    for ordering in (tm.MumpsOrdering.AMD, tm.MumpsOrdering.QAMD, tm.MumpsOrdering.PORD):
        r = tm.optimize_trajectory(p, options=tm.OptimizerOptions(max_refinements=0, ordering=ordering))
        assert r.ok, r.message
        assert abs(r.cost - base.cost) <= 1e-6 * abs(base.cost)
    threaded = tm.optimize_trajectory(p, options=tm.OptimizerOptions(max_refinements=0, threads=2))
    assert threaded.ok and threaded.iterations == base.iterations and threaded.cost == base.cost
    with pytest.raises(ValueError, match="threads = 0"):
        tm.optimize_trajectory(p, options=tm.OptimizerOptions(threads=0))
    with pytest.raises(ValueError, match="threads = 300 must be in 1..256"):
        tm.optimize_trajectory(p, options=tm.OptimizerOptions(threads=300))
