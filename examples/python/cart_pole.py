#!/usr/bin/env python3
"""Cart-pole swing-up from Python: optimize → TV-LQR gains → closed-loop simulation → figure.

1. optimizes the swing-up of examples/problems/cart_pole_swingup.json (direct collocation, Ipopt);
2. TV-LQR gains along the optimized trajectory (Q = diag(10, 10, 1, 1), R = 0.1, Qf = 100 I), the
   same weights as scripts/run_example.sh, sampled every 0.01 s;
3. simulates the nonlinear closed loop from three perturbed starts (seeded, σ = 0.05) and the
   open loop from the first;
4. writes output/python/cart_pole/{reference.csv, gains.csv, cart_pole.png}.

usage: python3 examples/python/cart_pole.py [OUTPUT_DIR]
"""
import pathlib
import sys

import _setup_path  # noqa: F401  (finds the build tree's trellis_mech)
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trellis_mech as tm  # noqa: E402

ROOT = _setup_path.ROOT


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ROOT / "output" / "python" / "cart_pole")
    out.mkdir(parents=True, exist_ok=True)

    problem = tm.load_problem(str(ROOT / "examples" / "problems" / "cart_pole_swingup.json"))
    model = problem.model
    result = tm.optimize_trajectory(problem)
    print(f"optimize: {result.status.name}, {result.iterations} iterations, cost {result.cost:.6g}, "
          f"max |defect| {result.constraint_violation:.1e}, {result.solve_time:.2f} s")
    if not result.ok:
        sys.exit(f"optimization failed: {result.message}")
    reference = result.trajectory
    reference.compute_state_derivatives(model)
    reference.write_csv(str(out / "reference.csv"))

    solution = tm.solve_tvlqr(model, reference, Q=np.array([10.0, 10.0, 1.0, 1.0]), R=0.1, Qf=100.0,
                              options=tm.TvlqrOptions(output_step=0.01))
    if not solution.ok:
        sys.exit(f"TV-LQR failed: {solution.describe()}")
    gains = solution.gains
    times = gains.times
    gains.write_csv(str(out / "gains.csv"))
    K0 = gains.evaluate(0.0)
    print(f"gains: {len(gains)} times, K(0) = {np.array2string(K0[0], precision=4)}, "
          f"max |K| = {np.abs(gains.gains).max():.4g}; Riccati {solution.steps} steps")

    rng = np.random.default_rng(1)
    x_start = reference.states[0]
    starts = np.array([x_start + 0.05 * rng.standard_normal(model.nx) for _ in range(3)])
    options = tm.SimulationOptions(output_step=0.01)
    closed = tm.simulate_closed_loop_many(model, reference, gains, starts, options=options)
    open_loop = tm.simulate_open_loop(model, reference, starts[0], options=options)
    for k, run in enumerate(closed):
        status = run.status.describe()
        print(f"closed loop {k + 1}: |x - x_ref| {run.tracking_error[0]:.3g} -> "
              f"{run.tracking_error[-1]:.3g} ({status})")
    final_open = open_loop.tracking_error[-1] if len(open_loop.tracking_error) else float("nan")
    print(f"open loop: |x - x_ref| {open_loop.tracking_error[0]:.3g} -> {final_open:.3g}"
          f" ({open_loop.status.describe()})")

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    names = model.state_names
    X, U = reference.sample(times)
    for ax, i in zip(axes.flat[:2], (0, 1)):
        ax.plot(times, X[:, i], "k", lw=2, label="reference")
        for k, run in enumerate(closed):
            ax.plot(run.trajectory.times, run.trajectory.states[:, i], lw=1, label=f"closed loop {k + 1}")
        ax.plot(open_loop.trajectory.times, open_loop.trajectory.states[:, i], "r--", lw=1, label="open loop")
        ax.set_ylabel(names[i])
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].plot(times, U[:, 0], "k", lw=2)
    for run in closed:
        axes[1, 0].plot(run.trajectory.times, run.trajectory.inputs[:, 0], lw=1)
    axes[1, 0].set_ylabel(model.input_names[0])
    for j in range(model.nx):
        axes[1, 1].plot(gains.times, gains.gains[:, 0, j], label=f"K[{names[j]}]")
    axes[1, 1].set_ylabel("gain")
    axes[1, 1].legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    fig.suptitle("cart-pole swing-up: optimized reference, TV-LQR closed loop (trellis_mech)")
    fig.tight_layout()
    fig.savefig(out / "cart_pole.png", dpi=110)
    print(f"wrote {out / 'cart_pole.png'}, {out / 'gains.csv'}, {out / 'reference.csv'}")
    return 0 if all(run.ok and run.tracking_error[-1] < run.tracking_error[0] for run in closed) else 1


if __name__ == "__main__":
    sys.exit(main())
