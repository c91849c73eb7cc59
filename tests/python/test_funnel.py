"""trellis_mech.estimate_funnel and CostToGo (analysis/funnel.hpp): the same estimate as
`trellis funnel`, as arrays; the same samples for any thread count; bad input as ValueError."""
import math

import numpy as np
import pytest

from conftest import SCENES, TRAJECTORIES


def cart_pole_funnel_inputs(tm):
    model = tm.load_scene(str(SCENES / "cart_pole.json")).model
    ref = tm.Trajectory.read_csv(str(TRAJECTORIES / "cart_pole_upright.csv"))
    ref.compute_state_derivatives(model)
    sol = tm.solve_tvlqr(model, ref, Q=np.diag([10.0, 10.0, 1.0, 1.0]), R=0.1)
    assert sol.ok, sol.status.describe()
    return model, ref, sol.gains, tm.CostToGo(sol.gains.times, sol.S)


def test_funnel_arrays_and_threads(tm):
    model, ref, gains, S = cart_pole_funnel_inputs(tm)
    options = tm.SimulationOptions(input_lower=[-10.0], input_upper=[10.0])
    kwargs = dict(levels=[1.0, 10.0, 100.0], samples=4, seed=5, start_times=[0.0, 1.0], options=options)
    one = tm.estimate_funnel(model, ref, gains, S, threads=1, **kwargs)
    two = tm.estimate_funnel(model, ref, gains, S, threads=2, **kwargs)
    assert one.ok and two.ok
    assert one.successes.shape == (2, 3) and (one.samples == 4).all()
    assert one.dx0.shape == (24, 4) and one.success.shape == (24,)
    # Bit-identical for 1 and 2 threads.
    assert np.array_equal(one.dx0, two.dx0) and np.array_equal(one.success, two.success)
    assert np.array_equal(one.final_level, two.final_level, equal_nan=True)
    assert one.json() == two.json()
    # Every start lies on its level set; rho is the largest level with no failure up to it.
    for g in range(24):
        t = one.start_times[one.sample_start[g]]
        assert S.level(t, one.dx0[g]) == pytest.approx(one.levels[one.sample_level[g]], rel=1e-12)
    for s in range(2):
        clean = np.cumprod(one.successes[s] == one.samples[s]).astype(bool)
        assert one.rho[s] == (one.levels[clean].max() if clean.any() else 0.0)
    assert one.failure_bound == pytest.approx(1 - 0.05 ** 0.25)


def test_funnel_bad_input(tm):
    model, ref, gains, S = cart_pole_funnel_inputs(tm)
    with pytest.raises(ValueError, match=r"levels\[1\] = inf"):
        tm.estimate_funnel(model, ref, gains, S, levels=[1.0, math.inf])
    with pytest.raises(ValueError, match="samples = 0"):
        tm.estimate_funnel(model, ref, gains, S, levels=[1.0], samples=0)
    wrong = tm.CostToGo([0.0, 3.0], np.stack([np.eye(2), np.eye(2)]))
    with pytest.raises(ValueError, match="cost-to-go is 2x2"):
        tm.estimate_funnel(model, ref, gains, wrong, levels=[1.0])


def test_cost_to_go_csv_round_trip(tm, tmp_path):
    _, _, gains, S = cart_pole_funnel_inputs(tm)
    path = tmp_path / "S.csv"
    S.write_csv(str(path))
    back = tm.CostToGo.read_csv(str(path))
    assert np.array_equal(back.S, S.S) and np.array_equal(back.times, S.times)
