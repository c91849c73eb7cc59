#!/usr/bin/env python3
"""Plots of a trellis run from its CSV files: states, inputs, gains and tracking error against time.

    plot_run.py --reference TRAJ.csv [--scene SCENE.json | --accelerations QDD.csv]
                [--closed CLOSED.csv ...]
                [--gains GAINS.csv] [--controllability CONTROLLABILITY.csv] --out DIR
                [--title NAME] [--configs a,b,...] [--trellis PROGRAM] [--closed-after-go]

TRAJ.csv and CLOSED.csv use the trajectory layout (t, configurations, d + configurations,
inputs); GAINS.csv the gains layout (t, K row-major; uff columns ignored). Writes DIR/states.png, DIR/inputs.png,
and, when given, DIR/gains.png, DIR/tracking_error.png and DIR/controllability.png (from a
CSV t,dimension,rank,smallest_singular_value). Uses matplotlib's Agg backend (no
display needed); Debian's python3-matplotlib is enough.

The tracking error is measured against the reference as every trellis tool reads it
(control/include/trellis/core/trajectory.hpp): the state is the cubic Hermite spline through
the knots with the knot derivatives x'_k = [dq_k; q''(q_k, dq_k, u_k)], which is what
`trellis simulate` reports. q'' comes from the scene's exact dynamics: with --scene, one
`trellis linearize -` per knot (the scene with the knot as its state, on standard input). Without
--scene the velocity part of the spline has no derivatives and the error plot falls back to linear
interpolation between knots, says so in its title and on standard error (it overstates the error
between knots by O(h²)). --accelerations QDD.csv gives q''_k directly instead (header t and the
configuration names, one row per reference knot — e.g. the reference's stored state derivatives,
which is what simulate uses; no trellis process per knot).

With --closed-after-go the plots that need no closed loop (gains, controllability) are made
first; then the script reads one line from standard input and goes on only if it is "go" (the
caller has written the --closed files). A caller can so start this one process early and let
matplotlib's start-up and the first plots overlap its own work; end of input without "go" (the
caller failed) ends the script with an error.
"""
import argparse
import bisect
import csv
import json
import math
import os
import subprocess
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_csv(path):
    """Header and columns (lists of floats) of a CSV file; exits with a message on bad input."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        sys.exit(f"plot_run.py: cannot read {path}: {e.strerror}")
    # Comment lines before the header ('# trellis gain schedule: ...') carry metadata, not data.
    first = 0
    while first < len(rows) and rows[first] and rows[first][0].lstrip().startswith("#"):
        first += 1
    if len(rows) - first < 2:
        sys.exit(f"plot_run.py: {path}: needs a header and at least one data row")
    header = [h.strip() for h in rows[first]]
    columns = [[] for _ in header]
    for line, row in enumerate(rows[first + 1:], start=first + 2):
        if not row:
            continue
        if len(row) != len(header):
            sys.exit(f"plot_run.py: {path}:{line}: {len(row)} columns, header has {len(header)}")
        for j, value in enumerate(row):
            try:
                columns[j].append(float(value))
            except ValueError:
                sys.exit(f"plot_run.py: {path}:{line}: column '{header[j]}' is not a number: {value!r}")
    return header, columns


class Trajectory:
    """The trajectory CSV layout: t, n configurations, their d-prefixed velocities, then inputs
    (and optionally their rates, rate_<input>)."""

    def __init__(self, path):
        header, columns = read_csv(path)
        if header[0] != "t":
            sys.exit(f"plot_run.py: {path}: the first column must be 't', not '{header[0]}'")
        names = header[1:]
        n = None
        for candidate in range(len(names) // 2, 0, -1):
            if all(names[candidate + i] == "d" + names[i] for i in range(candidate)):
                n = candidate
                break
        if n is None:
            sys.exit(f"plot_run.py: {path}: no 'q..., dq...' block found in the header")
        self.path = path
        self.t = columns[0]
        self.configs = names[:n]
        # Inputs up to the optional rate_<input> columns (the knot derivatives of the inputs for
        # the cubic input rule, trajectory.hpp); the rates are kept apart, not plotted as inputs.
        rest = names[2 * n:]
        m = next((j for j, name in enumerate(rest) if name.startswith("rate_")), len(rest))
        self.inputs = rest[:m]
        self.q = columns[1:1 + n]
        self.dq = columns[1 + n:1 + 2 * n]
        self.u = columns[1 + 2 * n:1 + 2 * n + m]
        self.rates = columns[1 + 2 * n + m:]

        self.qdd = None  # q'' at the knots (n lists), from compute_accelerations

    def compute_accelerations(self, scene_path, trellis):
        """q''_k at every knot from the scene's exact dynamics (`trellis linearize -`)."""
        try:
            with open(scene_path) as f:
                scene = json.load(f)
        except (OSError, ValueError) as e:
            sys.exit(f"plot_run.py: cannot read the scene {scene_path}: {e}")
        qdd = [[] for _ in self.configs]
        for k in range(len(self.t)):
            scene["state"] = {
                "q": {name: self.q[i][k] for i, name in enumerate(self.configs)},
                "dq": {name: self.dq[i][k] for i, name in enumerate(self.configs)},
                "u": {name: self.u[j][k] for j, name in enumerate(self.inputs)},
            }
            run = subprocess.run([trellis, "linearize", "--compact", "-"], input=json.dumps(scene),
                                 capture_output=True, text=True)
            if run.returncode != 0:
                sys.exit(f"plot_run.py: trellis linearize failed at knot {k} (t = {self.t[k]}): "
                         f"{run.stderr.strip()}")
            values = json.loads(run.stdout)["qdd"]
            for i in range(len(self.configs)):
                qdd[i].append(float(values[i]))
        self.qdd = qdd

    def read_accelerations(self, path):
        """q''_k at every knot from a CSV: t, then one column per configuration (same knots)."""
        header, columns = read_csv(path)
        if header != ["t"] + self.configs:
            sys.exit(f"plot_run.py: {path}: expected the columns t,{','.join(self.configs)}")
        if len(columns[0]) != len(self.t) or any(
                abs(a - b) > 1e-9 * max(1.0, abs(b)) for a, b in zip(columns[0], self.t)):
            sys.exit(f"plot_run.py: {path}: its times are not the reference's {len(self.t)} knots")
        self.qdd = columns[1:]

    def state_at(self, t):
        """x(t): the cubic Hermite spline of trajectory.hpp when the knot accelerations are known
        (the q part always uses the exact knot velocities), else linear between knots."""
        ts = self.t
        if len(ts) == 1:
            return [c[0] for c in self.q + self.dq]
        t = min(max(t, ts[0]), ts[-1])
        k = min(max(bisect.bisect_right(ts, t) - 1, 0), len(ts) - 2)
        h = ts[k + 1] - ts[k]
        s = (t - ts[k]) / h
        # Cubic Hermite basis on [0, 1].
        h00 = 2 * s ** 3 - 3 * s ** 2 + 1
        h10 = s ** 3 - 2 * s ** 2 + s
        h01 = -2 * s ** 3 + 3 * s ** 2
        h11 = s ** 3 - s ** 2

        def hermite(c, d):
            return h00 * c[k] + h10 * h * d[k] + h01 * c[k + 1] + h11 * h * d[k + 1]

        if self.qdd is None:
            return [c[k] + s * (c[k + 1] - c[k]) for c in self.q + self.dq]
        return ([hermite(self.q[i], self.dq[i]) for i in range(len(self.q))] +
                [hermite(self.dq[i], self.qdd[i]) for i in range(len(self.dq))])


def plot_states(ref, closed, selected, out, title):
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, name in enumerate(ref.configs):
        if selected and name not in selected:
            continue
        c = colors[i % len(colors)]
        axes[0].plot(ref.t, ref.q[i], "--", color=c, lw=1.2, label=f"{name} (reference)")
        axes[1].plot(ref.t, ref.dq[i], "--", color=c, lw=1.2)
        for k, run in enumerate(closed):
            axes[0].plot(run.t, run.q[i], color=c, lw=0.9, alpha=0.8,
                         label=f"{name} (closed loop)" if k == 0 else None)
            axes[1].plot(run.t, run.dq[i], color=c, lw=0.9, alpha=0.8)
    axes[0].set_ylabel("configuration")
    axes[1].set_ylabel("velocity")
    axes[1].set_xlabel("t [s]")
    axes[0].legend(fontsize=7, ncol=2)
    axes[0].set_title(f"{title}: states")
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "states.png"), dpi=110)
    plt.close(fig)


def plot_inputs(ref, closed, out, title):
    if not ref.inputs:
        return
    fig, ax = plt.subplots(figsize=(9, 4))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, name in enumerate(ref.inputs):
        c = colors[i % len(colors)]
        ax.plot(ref.t, ref.u[i], "--", color=c, lw=1.2, label=f"{name} (reference)")
        for k, run in enumerate(closed):
            ax.plot(run.t, run.u[i], color=c, lw=0.9, alpha=0.8,
                    label=f"{name} (closed loop)" if k == 0 else None)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("input")
    ax.set_title(f"{title}: inputs")
    ax.grid(alpha=0.3)
    if len(ref.inputs) <= 12:
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "inputs.png"), dpi=110)
    plt.close(fig)


def plot_gains(path, out, title):
    header, columns = read_csv(path)
    t = columns[0]
    # Columns are K row-major, then (sampled gains) the feed-forward uff[<input>], not plotted.
    # Named files ('K[<input>|<state>]', older 'K_<input>_<state>') say m and nx in their
    # metadata line; old files name the indices ('K_i_j').
    with open(path) as f:
        meta = re.search(r"m=(\d+) nx=(\d+)", f.readline())
    rows = {}
    for index, (name, col) in enumerate(zip(header[1:], columns[1:])):
        if name.startswith("uff"):
            break
        if not (name.startswith("K_") or name.startswith("K[")):
            sys.exit(f"plot_run.py: {path}: gain column '{name}' is not K[<input>|<state>]")
        if meta:
            row = index // int(meta.group(2))
        else:
            parts = name.split("_")
            if len(parts) != 3 or not parts[1].isdigit():
                sys.exit(f"plot_run.py: {path}: gain column '{name}' is not K_i_j")
            row = int(parts[1])
        rows.setdefault(row, []).append(col)
    fig, ax = plt.subplots(figsize=(9, 4))
    for i in sorted(rows):
        norm = [math.sqrt(sum(c[k] ** 2 for c in rows[i])) for k in range(len(t))]
        ax.semilogy(t, [max(v, 1e-12) for v in norm], lw=1.1, label=f"‖K row {i}‖")
    # Logarithmic: the gains of a finite-horizon LQR spike near t_f (Q_f, the shrinking horizon),
    # and on a linear axis the spike flattens everything before it.
    ax.set_xlabel("t [s]")
    ax.set_ylabel("gain norm (log scale)")
    ax.set_title(f"{title}: feedback gains (row norms of K(t))")
    ax.grid(alpha=0.3, which="both")
    ax.grid(alpha=0.3)
    if len(rows) <= 12:
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "gains.png"), dpi=110)
    plt.close(fig)


def plot_error(ref, closed, out, title):
    fig, ax = plt.subplots(figsize=(9, 4))
    for run in closed:
        err = []
        for k, t in enumerate(run.t):
            x = [c[k] for c in run.q + run.dq]
            xr = ref.state_at(t)
            err.append(max(1e-16, math.sqrt(sum((a - b) ** 2 for a, b in zip(x, xr)))))
        ax.semilogy(run.t, err, lw=0.9, alpha=0.8, label=os.path.splitext(os.path.basename(run.path))[0])
    if len(closed) <= 12:
        ax.legend(fontsize=7, ncol=2)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("‖x − x_ref‖₂")
    how = "Hermite reference as in simulate" if ref.qdd is not None else "LINEAR reference (no --scene)"
    ax.set_title(f"{title}: tracking error ({len(closed)} run(s); {how})")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "tracking_error.png"), dpi=110)
    plt.close(fig)


def plot_controllability(path, out, title):
    header, columns = read_csv(path)
    needed = ["t", "dimension", "rank", "smallest_singular_value"]
    if header != needed:
        sys.exit(f"plot_run.py: {path}: expected the columns {needed}, got {header}")
    t, dim, rank, sigma = columns
    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    axes[0].semilogy(t, [max(s, 1e-300) for s in sigma], lw=1.1)
    axes[0].set_ylabel("σ_min of [B, AB, …]")
    axes[0].set_title(f"{title}: controllability on the constraint manifold")
    axes[1].plot(t, dim, "--", lw=1.2, label="manifold dimension")
    axes[1].plot(t, rank, lw=1.1, label="rank")
    axes[1].set_ylabel("rank")
    axes[1].set_xlabel("t [s]")
    axes[1].legend(fontsize=8)
    for a in axes:
        a.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "controllability.png"), dpi=110)
    plt.close(fig)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", required=True)
    p.add_argument("--closed", action="append", default=[])
    p.add_argument("--gains")
    p.add_argument("--scene", help="scene of the reference: Hermite reference for the tracking error")
    p.add_argument("--accelerations",
                   help="CSV t,<configs>: q'' at the reference knots (Hermite reference without --scene)")
    p.add_argument("--trellis", default=os.environ.get("TRELLIS", os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "..", "build", "cli", "trellis")),
        help="the trellis program (default $TRELLIS or build/cli/trellis)")
    p.add_argument("--controllability", help="CSV: t,dimension,rank,smallest_singular_value")
    p.add_argument("--out", required=True)
    p.add_argument("--title", default="trellis")
    p.add_argument("--configs", default="", help="comma-separated configurations to plot (default: all)")
    p.add_argument("--closed-after-go", action="store_true",
                   help="read the --closed files only after a line 'go' on standard input")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    ref = Trajectory(args.reference)
    if args.closed_after_go:
        if args.gains:
            plot_gains(args.gains, args.out, args.title)
            args.gains = None
        if args.controllability:
            plot_controllability(args.controllability, args.out, args.title)
            args.controllability = None
        line = sys.stdin.readline()
        if line.strip() != "go":
            sys.exit("plot_run.py: standard input ended without 'go': the closed-loop files were "
                     "not announced (did the caller fail?)")
    closed = [Trajectory(c) for c in args.closed]
    for run in closed:
        if run.configs != ref.configs:
            sys.exit(f"plot_run.py: {run.path}: configurations {run.configs} differ from the reference's")
    selected = [s for s in args.configs.split(",") if s]
    plot_states(ref, closed, selected, args.out, args.title)
    plot_inputs(ref, closed, args.out, args.title)
    if args.gains:
        plot_gains(args.gains, args.out, args.title)
    if closed:
        if args.accelerations:
            ref.read_accelerations(args.accelerations)
        elif args.scene:
            ref.compute_accelerations(args.scene, args.trellis)
        else:
            print("plot_run.py: no --scene or --accelerations: the tracking error is measured against the reference "
                  "interpolated LINEARLY, not as simulate does (Hermite)", file=sys.stderr)
        plot_error(ref, closed, args.out, args.title)
    if args.controllability:
        plot_controllability(args.controllability, args.out, args.title)
    print(f"plot_run.py: plots written to {args.out}/")


if __name__ == "__main__":
    main()
