#!/usr/bin/env python3
"""The paper's Sec. IV example from Python: the exact linearization of the constrained double
pendulum (examples/scenes/paper_pendulum.json) at the state of shared/paper/ERRATA.md, with u0 = 0
and u0 = 2, checked against the verified table that ERRATA.md prints (read from the file, 7
decimals); then the linearization on the constraint manifold at a consistent state.
Exit status 0 when every entry agrees to 1e-6.

usage: python3 examples/python/paper_example.py [path/to/ERRATA.md]
(default: $TRELLIS_SHARED_DIR/paper/ERRATA.md, else ../shared/paper/ERRATA.md beside the repository)
"""
import math
import os
import pathlib
import re
import sys

import _setup_path  # noqa: F401
import numpy as np
import trellis_mech as tm

ROOT = _setup_path.ROOT


def errata_tables(path):
    """{u0: 2x5 array [dqdd/dq | dqdd/ddq | dqdd/du]} from ERRATA.md's "Section IV example"."""
    text = pathlib.Path(path).read_text(encoding="utf-8")
    number = lambda s: float(s.replace("−", "-"))  # noqa: E731  (ERRATA.md uses U+2212)
    rows = [[number(v) for v in m.group(1).split("|")]
            for m in (re.match(r"\s*\|\s*θ̈[12]\s*\|(.*)\|\s*$", line) for line in text.splitlines()) if m]
    match = re.search(r"columns\s+are \[([^\]]+)\]", text)
    if len(rows) != 2 or not match:
        raise ValueError(f"{path}: the Section IV table was not found")
    u0 = np.array(rows)
    u2 = u0.copy()
    u2[:, :2] = [[number(v) for v in row.split(",")] for row in match.group(1).split(";")]
    return {0.0: u0, 2.0: u2}


def main():
    shared = pathlib.Path(os.environ.get("TRELLIS_SHARED_DIR", ROOT.parent / "shared"))
    errata = sys.argv[1] if len(sys.argv) > 1 else shared / "paper" / "ERRATA.md"
    tables = errata_tables(errata)
    model = tm.load_scene(str(ROOT / "examples" / "scenes" / "paper_pendulum.json")).model
    data = tm.Data(model)
    q0, dq0 = np.array([0.5246, 1.0472]), np.array([1.0, -2.00116])
    columns = [f"d/d{c}" for c in model.config_names] + [f"d/d{c}'" for c in model.config_names] + ["d/du"]
    worst = 0.0
    np.set_printoptions(precision=7, suppress=True, linewidth=120)
    for u0, reference in tables.items():
        status = tm.compute_linearization(model, data, q0, dq0, [u0])
        if not status.ok:
            print(f"u0 = {u0}: the dynamics failed: {status.message}")
            return 1
        table = np.hstack([data.dqdd_dq, data.dqdd_ddq, data.dqdd_du])
        diff = np.abs(table - reference).max()
        worst = max(worst, diff)
        print(f"u0 = {u0:g}: q = {q0}, dq = {dq0}   columns {' '.join(columns)}")
        print("  trellis_mech\n", table, "\n  ERRATA.md\n", reference)
        print(f"  max |difference| = {diff:.1e}\n")

    # On the manifold: h(pi/6, pi/3) = 0, dq in the null space of A(q).
    q = np.array([math.pi / 6, math.pi / 3])
    tm.compute_constraints(model, data, q, np.zeros(2))
    a = data.constraint_jacobian[0]
    lin = tm.linearize(model, q, [1.0, -a[0] / a[1]], [0.0], data=data, tangent=True)
    print("consistent state q = (pi/6, pi/3): tangent dimension", lin.tangent_basis.shape[1])
    print("  reduced A = T^T A T\n", lin.reduced_A, "\n  reduced B = T^T B\n", lin.reduced_B)
    ok = worst <= 1e-6
    print(f"\npaper_example.py: max |difference| {worst:.1e} (tolerance 1e-6): {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
