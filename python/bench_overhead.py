#!/usr/bin/env python3
"""Per-call overhead of trellis_mech against C++ for the exact linearization (issue 14's target:
under 2 µs per call beyond the C++ time).

For each scene (pendulum, hand; at the state stored in the scene) it measures, in one process:
  cpp        computeLinearization in a C++ loop (trellis_mech._trellis_mech._time_linearization_loop:
             the same Model, Data and inputs, no Python in the loop);
  out        compute_linearization(model, data, q, dq, u, A=A, B=B): the hot-loop form, writing
             into preallocated NumPy arrays;
  status     compute_linearization(model, data, q, dq, u): results stay in data;
  linearize  trellis_mech.linearize(model, q, dq, u, data=data): fresh copies of A, B, qdd, λ, M.
Each figure is the per-call time of `--number` calls, taken over `--rounds` rounds; the table gives
the minimum and the median (the spread on a shared machine), and the overhead = Python − C++
(both minima).

usage: python3 python/bench_overhead.py [--number N] [--rounds R] [--json FILE]
(with PYTHONPATH=build/python, or `source build/python/env.sh`)
"""
import argparse
import json
import pathlib
import statistics
import sys
import timeit

try:
    import trellis_mech as tm
except ImportError:
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "build" / "python"))
    import trellis_mech as tm
from trellis_mech import _trellis_mech as native

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]


def measure(fn, number, rounds):
    times = [t / number for t in timeit.repeat(fn, number=number, repeat=rounds)]
    return min(times), statistics.median(times)


def bench(name, number, rounds):
    scene = tm.load_scene(str(ROOT / "examples" / "scenes" / f"{name}.json"))
    model = scene.model
    data = tm.Data(model)
    q, dq, u = scene.q, scene.dq, scene.u
    A, B = np.empty((model.nx, model.nx)), np.empty((model.nx, model.nu))
    cpp = [native._time_linearization_loop(model, data, q, dq, u, number) for _ in range(rounds)]
    rows = {"cpp": (min(cpp), statistics.median(cpp))}
    rows["out"] = measure(lambda: tm.compute_linearization(model, data, q, dq, u, A=A, B=B), number, rounds)
    rows["status"] = measure(lambda: tm.compute_linearization(model, data, q, dq, u), number, rounds)
    rows["linearize"] = measure(lambda: tm.linearize(model, q, dq, u, data=data), number, rounds)
    return model, rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--number", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--json")
    args = parser.parse_args()
    report = {}
    print(f"{'scene':10} {'call':10} {'min µs':>9} {'median µs':>10} {'overhead µs':>12}")
    for name in ("pendulum", "hand"):
        number = args.number if name == "pendulum" else max(args.number // 10, 50)
        model, rows = bench(name, number, args.rounds)
        report[name] = {"nq": model.nq, "nu": model.nu, "nc": model.nc, "calls_per_round": number}
        for call, (best, median) in rows.items():
            overhead = best - rows["cpp"][0]
            report[name][call] = {"min_us": best * 1e6, "median_us": median * 1e6,
                                  "overhead_us": overhead * 1e6}
            print(f"{name:10} {call:10} {best * 1e6:9.2f} {median * 1e6:10.2f} "
                  f"{'' if call == 'cpp' else f'{overhead * 1e6:12.2f}'}")
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
