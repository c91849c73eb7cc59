#!/usr/bin/env python3
"""The hand's TV-LQR gains from Python — steps 1 and 5 of examples/hand/hand_hold_job.cpp (the main job before issue 26)
with the same settings, then one closed loop:

1. the reference motion of examples/scenes/hand.json (the digits flex and return over 3 s on the
   grasp's constraint manifold, tendon tensions ≥ 0 by inverse dynamics; examples/hand);
2. controllability on the constraint manifold at the first knot;
3. TV-LQR on the constraint manifold: Q = I with 100 on the angles, R = I, Qf = Q, Riccati with
   rtol 1e-6, atol 1e-8, tangent basis by projected transport (2 substeps), as the main job does;
4. one closed loop from a seeded perturbation tangent to the manifold, tensions saturated at 0;
5. writes output/python/hand/{gains.csv, hand_gains.png}.

usage: python3 examples/python/hand_gains.py [OUTPUT_DIR]
"""
import pathlib
import sys
import time

import _setup_path  # noqa: F401
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trellis_mech as tm  # noqa: E402

ROOT = _setup_path.ROOT


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ROOT / "output" / "python" / "hand")
    out.mkdir(parents=True, exist_ok=True)
    if not hasattr(tm, "hand"):
        sys.exit("trellis_mech was built without the examples (TRELLIS_BUILD_EXAMPLES=OFF)")
    scene = tm.load_scene(str(ROOT / "examples" / "scenes" / "hand.json"))
    model = scene.model
    n, m = model.nq, model.nu
    print(f"hand: {n} coordinates, {m} tendons, {model.nc} constraint rows")

    start = time.perf_counter()
    motion = tm.hand.make_reference_motion(model, scene.q)
    if not motion.ok:
        sys.exit(f"reference motion: {motion.message}")
    reference = motion.trajectory
    print(f"reference: {len(reference)} knots on [0, {reference.end_time:g}] s, "
          f"max |h| {motion.constraint_residual.max():.1e} ({time.perf_counter() - start:.2f} s)")

    data = tm.Data(model)
    x0 = reference.states[0]
    report = tm.compute_controllability_at(model, data, x0[:n], x0[n:], reference.inputs[0])
    print(f"controllability at t = 0: rank {report.rank} of {report.dimension} on the manifold")

    Q = np.eye(2 * n)
    Q[:n, :n] *= 100.0  # angles matter more than rates
    start = time.perf_counter()
    solution = tm.solve_tvlqr(
        model, reference, Q=Q, R=1.0,
        options=tm.TvlqrOptions(
            riccati=tm.RiccatiOptions(rtol=1e-6, atol=1e-8),
            transport=tm.TangentTransportOptions(method=tm.TangentTransport.PROJECTED, substeps=2)))
    if not solution.ok:
        sys.exit(f"TV-LQR failed: {solution.describe()}")
    gains = solution.gains
    gains.write_csv(str(out / "gains.csv"))
    norms = np.linalg.norm(gains.gains, axis=(1, 2))
    print(f"gains: {len(gains)} x ({gains.nu} x {gains.nx}), {solution.steps} Riccati steps on "
          f"{solution.dimension} reduced states, max |K|_F {norms.max():.4g} "
          f"({time.perf_counter() - start:.2f} s)")

    rng = np.random.default_rng(1)
    T0 = tm.linearize(model, x0[:n], x0[n:], reference.inputs[0], tangent=True).tangent_basis
    z = rng.standard_normal(T0.shape[1])
    x_start = x0 + T0 @ (0.05 * z / np.linalg.norm(z))
    options = tm.SimulationOptions(method=tm.IntegrationMethod.BDF, rtol=1e-7, atol=1e-9,
                                   input_lower=np.zeros(m), input_upper=np.full(m, np.inf))
    start = time.perf_counter()
    run = tm.simulate_closed_loop(model, reference, gains, x_start, options=options)
    print(f"closed loop: |x - x_ref| {run.tracking_error[0]:.3g} -> {run.tracking_error[-1]:.3g}, "
          f"max drift {run.max_constraint_drift:.1e}, saturated {100 * run.saturated_fraction:.0f} % "
          f"({run.status.describe()}; {time.perf_counter() - start:.2f} s)")

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    axes[0].plot(gains.times, norms)
    axes[0].set_xlabel("t (s)")
    axes[0].set_ylabel("|K(t)|_F")
    axes[0].set_title(f"TV-LQR gain on the manifold ({gains.nu} x {gains.nx})")
    axes[1].semilogy(run.trajectory.times, run.tracking_error)
    axes[1].set_xlabel("t (s)")
    axes[1].set_ylabel("|x - x_ref|")
    axes[1].set_title("closed loop from a perturbed start")
    fig.tight_layout()
    fig.savefig(out / "hand_gains.png", dpi=110)
    print(f"wrote {out / 'gains.csv'}, {out / 'hand_gains.png'}")
    return 0 if run.ok and run.tracking_error[-1] < 0.5 * run.tracking_error[0] else 1


if __name__ == "__main__":
    sys.exit(main())
