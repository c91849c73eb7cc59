#!/usr/bin/env python3
"""Plots of the hand turning a ball (examples/main_job/hand_main_job) from its CSV files.

    plot_ball_turn.py --reference REFERENCE.csv [--closed CLOSED.csv ...] [--tracking TRACKING.csv]
                      --limits LIMITS.json --out DIR

REFERENCE.csv and CLOSED.csv: t, the coordinates, their rates (d<name>), the tendon tensions, and
each contact's force in its frame (lambda_<digit>_n, lambda_<digit>_t1, lambda_<digit>_t2).
TRACKING.csv: t, then ||x - x_ref|| of each run (run_<k>). LIMITS.json: examples/hand/
hand_ball_limits.json (friction_coefficient, normal_force_min, tension_max per tendon).
Writes DIR/ball_orientation.png (the ball's Z-Y-X angles against time), DIR/tensions.png (each
tendon against 0 and its maximum), DIR/contacts.png (each contact's normal force against the
margin and its friction ratio |lambda_t| / (mu lambda_n) against the cone's 1) and, with
--tracking, DIR/tracking_error.png. The reference is black dashed over the closed loops (grey).
Each PNG is written whole or not at all (a temporary file renamed). Matplotlib's Agg backend;
Debian's python3-matplotlib is enough.

    plot_ball_turn.py --arguments-on-stdin

imports first and then reads the arguments above from stdin, each ended by a NUL byte: a caller
starts it early, so that the imports (~0.4 s) overlap its own work, and sends the arguments when
the files exist (the main job does). Stdin closed with no arguments: exit status 3, nothing drawn.
"""
import argparse
import csv
import json
import math
import os
import sys

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

# Titles at a fixed height: left to matplotlib, every draw measures each axes' tick labels to
# lift its title clear of them (a quarter of the drawing time with 20 closed loops; nothing is
# drawn above these axes).
plt.rcParams["axes.titley"] = 1.0


def fail(message):
    sys.exit(f"plot_ball_turn.py: {message}")


def read_csv(path):
    """(header, {name: numpy array}) of a CSV with a header row; exits naming the file, row and
    column on bad input. numpy parses the numbers (the closed loops' files are ~1 MB each); where
    it refuses, the row-by-row reader below finds and names the bad field."""
    try:
        with open(path, newline="") as f:
            header = next(csv.reader([f.readline()]), [])
            try:
                data = np.loadtxt(f, delimiter=",", ndmin=2)
            except ValueError:
                data = None
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    if data is None or data.shape[0] < 1 or data.shape[1] != len(header):
        return read_csv_checked(path)
    return header, {name: data[:, j] for j, name in enumerate(header)}


def read_csv_checked(path):
    """read_csv's slow path: row by row, naming the first bad row and column (empty fields: NaN)."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    if len(rows) < 2:
        fail(f"{path}: no data rows")
    header = rows[0]
    columns = {name: [] for name in header}
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            fail(f"{path}: row {i} has {len(row)} fields, the header {len(header)}")
        for name, value in zip(header, row):
            try:
                columns[name].append(float(value) if value != "" else math.nan)
            except ValueError:
                fail(f"{path}: row {i}, column '{name}': '{value}' is not a number")
    return header, {name: np.array(v, dtype=float) for name, v in columns.items()}


def save(fig, out, name):
    """The figure as out/name, whole or not at all: drawn to a temporary file, then renamed; a
    failure on the way removes the temporary file and names the path."""
    path = os.path.join(out, name)
    tmp = path + ".tmp.png"
    try:
        fig.savefig(tmp, dpi=100)
        os.replace(tmp, path)
    except OSError as e:
        try:
            os.remove(tmp)
        except OSError:
            pass
        fail(f"{path}: {e.strerror or e}")
    finally:
        plt.close(fig)


def arguments():
    """The command line, or with --arguments-on-stdin alone the NUL-ended arguments on stdin."""
    if sys.argv[1:] != ["--arguments-on-stdin"]:
        return None  # argparse reads sys.argv
    data = sys.stdin.buffer.read()
    if not data:
        sys.exit(3)  # the caller gave up before sending any (its own failure says why)
    if not data.endswith(b"\0"):
        fail("--arguments-on-stdin: the arguments on stdin do not end with a NUL byte (cut short?)")
    return [os.fsdecode(a) for a in data[:-1].split(b"\0")]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", required=True)
    ap.add_argument("--closed", action="append", default=[])
    ap.add_argument("--tracking")
    ap.add_argument("--limits", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(arguments())
    try:
        with open(a.limits) as f:
            limits = json.load(f)
        mu = float(limits["friction_coefficient"])
        normal_min = float(limits["normal_force_min"])
        tension_max = {k: float(v) for k, v in limits["tension_max"].items()}
    except (OSError, KeyError, ValueError, TypeError, AttributeError) as e:
        fail(f"{a.limits}: {e}")
    header, ref = read_csv(a.reference)
    closed = [read_csv(p)[1] for p in a.closed]
    for p, c in zip(a.closed, closed):
        missing = [h for h in header if h not in c]
        if missing:
            fail(f"{p}: missing columns {', '.join(missing[:3])}")
    t = ref["t"]
    digits = [h[len("lambda_"):-len("_n")] for h in header if h.startswith("lambda_") and h.endswith("_n")]
    if not digits:
        fail(f"{a.reference}: no lambda_<digit>_n columns")
    tendons = [h for h in header if h in tension_max]
    if not tendons:
        fail(f"{a.reference}: no tendon columns named in {a.limits}")

    def grey(ax, curves):
        # The closed loops as one collection: one artist instead of one line each (matplotlib's
        # per-artist cost was most of the drawing with 20 loops on 37 axes).
        if curves:
            ax.add_collection(LineCollection([np.column_stack(c) for c in curves], colors="0.6", linewidths=0.7))

    def draw(ax, key, transform=lambda v: v):
        grey(ax, [(c["t"], transform(c[key])) for c in closed])
        ax.plot(t, transform(ref[key]), "k--", lw=1.2)

    def orientation():
        # The ball's orientation.
        # Fixed margins: matplotlib's constrained layout measured 2 of the script's 3 s (20 closed loops).
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
        fig.subplots_adjust(left=0.06, right=0.98, bottom=0.15, top=0.82, wspace=0.3)
        for ax, key in zip(axes, ("ball_yaw", "ball_pitch", "ball_roll")):
            if key not in ref:
                fail(f"{a.reference}: no column '{key}'")
            draw(ax, key, np.degrees)
            ax.set_title(key)
            ax.set_xlabel("t [s]")
            ax.set_ylabel("angle [deg]")
        fig.suptitle("ball orientation (Z-Y-X angles): reference dashed, closed loops grey")
        save(fig, a.out, "ball_orientation.png")

    def tensions():
        # Tensions against their bounds.
        cols = 6
        rows = math.ceil(len(tendons) / cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3 * cols, 2.2 * rows), squeeze=False)
        fig.subplots_adjust(left=0.05, right=0.99, bottom=0.04, top=0.93, wspace=0.35, hspace=0.45)
        for ax, name in zip(axes.flat, tendons):
            draw(ax, name)
            ax.axhline(0.0, color="tab:red", lw=0.8)
            ax.axhline(tension_max[name], color="tab:red", lw=0.8, ls=":")
            top = max([float(np.max(ref[name]))] + [float(np.max(c[name])) for c in closed])
            ax.set_ylim(-0.05 * tension_max[name], max(1.15 * top, 0.1 * tension_max[name]))
            ax.set_title(f"{name} (max {tension_max[name]:g} N)", fontsize=9)
            ax.set_ylabel("tension [N]", fontsize=8)
        for ax in list(axes.flat)[len(tendons):]:
            ax.axis("off")
        fig.suptitle("tendon tensions: reference dashed, closed loops grey; 0 red, u_max red dotted (off scale when far)")
        save(fig, a.out, "tensions.png")

    def contacts():
        # Contacts: normal force and friction ratio.
        def ratio(lam):
            n, t1, t2 = lam[f"lambda_{d}_n"], lam[f"lambda_{d}_t1"], lam[f"lambda_{d}_t2"]
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(n > 0, np.hypot(t1, t2) / (mu * n), np.inf)

        fig, axes = plt.subplots(2, len(digits), figsize=(3.2 * len(digits), 5.6), squeeze=False)
        fig.subplots_adjust(left=0.06, right=0.98, bottom=0.09, top=0.88, wspace=0.35, hspace=0.3)
        for j, d in enumerate(digits):
            ax = axes[0][j]
            draw(ax, f"lambda_{d}_n")
            ax.axhline(normal_min, color="tab:red", lw=0.8)
            ax.set_title(f"{d}: normal force", fontsize=9)
            ax.set_ylabel("lambda_n [N]", fontsize=8)
            ax = axes[1][j]
            grey(ax, [(c["t"], ratio(c)) for c in closed])
            ax.plot(t, ratio(ref), "k--", lw=1.2)
            ax.axhline(1.0, color="tab:red", lw=0.8)
            ax.set_ylim(0.0, 1.1)
            ax.set_title(f"{d}: |lambda_t| / (mu lambda_n)", fontsize=9)
            ax.set_xlabel("t [s]")
        fig.suptitle(f"contacts (mu = {mu:g}): normal force against the margin {normal_min:g} N, friction ratio against the cone (1)")
        save(fig, a.out, "contacts.png")

    def tracking():
        if a.tracking:
            th, tr = read_csv(a.tracking)
            fig, ax = plt.subplots(figsize=(7, 4))
            fig.subplots_adjust(left=0.13, right=0.97, bottom=0.12, top=0.92)
            for name in th[1:]:
                keep = (tr[name] > 0) & np.isfinite(tr[name])
                if keep.any():
                    ax.semilogy(tr["t"][keep], tr[name][keep], lw=0.8)
            ax.set_xlabel("t [s]")
            ax.set_ylabel("||x - x_ref|| [rad, m, rad/s, m/s]")
            ax.set_title("tracking error of each closed loop at the reference's knots")
            save(fig, a.out, "tracking_error.png")

    # The figures are independent: the tensions' 23 axes (about half of the drawing, which is
    # mostly matplotlib's tick layout) in a child process, the other three here.
    sys.stdout.flush()
    sys.stderr.flush()
    child = os.fork() if hasattr(os, "fork") else None
    if child == 0:
        code = 0
        try:
            tensions()
        except SystemExit as e:  # fail(): its message
            print(e, file=sys.stderr)
            code = 1
        except BaseException as e:  # noqa: BLE001 - any error is the child's failure
            print(f"plot_ball_turn.py: tensions.png: {e!r}", file=sys.stderr)
            code = 1
        sys.stderr.flush()
        os._exit(code)
    if child is None:
        tensions()
    status = 0
    try:
        orientation()
        contacts()
        tracking()
    finally:  # a failure here still waits for the child: nothing is left drawing after the exit
        if child:
            _, status = os.waitpid(child, 0)
    if child and not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0):
        fail("tensions.png was not written (its process failed, see above)")


if __name__ == "__main__":
    main()
