#!/usr/bin/env python3
"""The paper's Sec. IV example from Python: the exact linearization of the constrained double
pendulum (examples/scenes/paper_pendulum.json) at the state of docs/paper_errata.md, with u0 = 0
and u0 = 2, checked against the verified table that page prints (read from the file, 7
decimals); then the linearization on the constraint manifold at a consistent state.
Exit status 0 when every entry agrees to 1e-6.

usage: python3 examples/python/paper_example.py [path/to/paper_errata.md]
(default: docs/paper_errata.md of this source tree)
"""
import math
import pathlib
import re
import sys

import _setup_path  # noqa: F401
import numpy as np
import trellis_mech as tm

ROOT = _setup_path.ROOT


def errata_tables(path):
    """{u0: 2x5 array [dqdd/dq | dqdd/ddq | dqdd/du]} from the page's "Verified linearization" table,
    whose rows are | u0 | row | five values |."""
    text = pathlib.Path(path).read_text(encoding="utf-8")
    number = lambda s: float(s.replace("−", "-"))  # noqa: E731  (the page uses U+2212)
    tables = {}
    for line in text.splitlines():
        m = re.match(r"\s*\|\s*([0-9.]+)\s*\|\s*θ̈[₁₂]\s*\|(.*)\|\s*$", line)
        if m:
            tables.setdefault(float(m.group(1)), []).append([number(v) for v in m.group(2).split("|")])
    if sorted(tables) != [0.0, 2.0] or any(len(rows) != 2 for rows in tables.values()):
        raise ValueError(f"{path}: the verified table (rows u0 = 0 and 2) was not found")
    return {u0: np.array(rows) for u0, rows in sorted(tables.items())}


def main():
    errata = sys.argv[1] if len(sys.argv) > 1 else ROOT / "docs" / "paper_errata.md"
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
        print("  trellis_mech\n", table, "\n  verified\n", reference)
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
