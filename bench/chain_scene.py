#!/usr/bin/env python3
"""Writes the `trellis gains` end-to-end case of issue 11: a damped planar chain of N links
(default 20: 40 states), each a revolute joint with a torque input and a 0.1 kg point mass 0.1 m
below it, gravity on, viscous damping 0.1 on every joint, held hanging at rest for 2 s
(41 knots, q = q' = u = 0: the hanging equilibrium).

    python3 bench/chain_scene.py OUTDIR [N]
    trellis gains OUTDIR/chain.json --trajectory OUTDIR/hang.csv --Q 10 --R 1 --rtol 1e-6 --out K.csv
"""
import json
import os
import sys


def link(i, n):
    body = {"name": f"m{i}", "type": "ty", "value": -0.1, "mass": {"m": 0.1},
            "children": [link(i + 1, n)] if i < n else []}
    return {"name": f"l{i}", "type": "rz", "config": f"q{i}", "children": [body]}


def main():
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 20
    os.makedirs(out, exist_ok=True)
    scene = {
        "name": f"chain{n}",
        "description": f"{n}-link damped planar chain hanging under gravity, a torque at every joint",
        "frames": [link(1, n)],
        "potentials": [{"type": "gravity", "g": [0.0, -9.81, 0.0]}],
        "forces": [{"type": "config_force", "config": f"q{i}", "input": f"u{i}"}
                   for i in range(1, n + 1)] + [{"type": "damping", "default": 0.1}],
        "state": {"q": {f"q{i}": 0.0 for i in range(1, n + 1)},
                  "dq": {f"q{i}": 0.0 for i in range(1, n + 1)}},
    }
    with open(os.path.join(out, "chain.json"), "w") as f:
        json.dump(scene, f, indent=1)
    names = ([f"q{i}" for i in range(1, n + 1)] + [f"dq{i}" for i in range(1, n + 1)] +
             [f"u{i}" for i in range(1, n + 1)])
    with open(os.path.join(out, "hang.csv"), "w") as f:
        f.write(",".join(["t"] + names) + "\n")
        for k in range(41):
            f.write(",".join([repr(k * 0.05)] + ["0"] * (3 * n)) + "\n")


if __name__ == "__main__":
    main()
