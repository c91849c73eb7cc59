#!/usr/bin/env python3
"""Markdown tables from trellis_bench_riccati's JSON output.

    trellis_bench_riccati --benchmark_format=json --benchmark_out=riccati.json ...
    python3 bench/riccati_report.py riccati.json [--target 1e-6]

Prints one row per run (method x n x tolerance: CPU and wall time, relative error of S(t0) and the
worst over 21 times, steps, right-hand sides, GMRES iterations, preconditioner solves) and, per
method and n, the cheapest run whose error of S(t0) is at most --target.
"""
import argparse
import json
import sys


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("json_file")
    parser.add_argument("--target", type=float, default=1e-6, help="error target for the summary")
    args = parser.parse_args()
    with open(args.json_file) as f:
        data = json.load(f)
    rows = []
    for b in data["benchmarks"]:
        if b.get("run_type", "iteration") != "iteration":
            continue
        scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
        rows.append({
            "method": b.get("label", "?"),
            "nx": int(b["nx"]),
            "rtol": b["rtol"],
            "cpu": b["cpu_time"] * scale,
            "wall": b["real_time"] * scale,
            "err0": b["rel_err_t0"],
            "errmax": b["max_rel_err"],
            "steps": int(b["steps"]),
            "rhs": int(b["rhs"]),
            "lin": int(b.get("lin_iters", 0)),
            "psolve": int(b.get("psolves", 0)),
            "ok": int(b["ok"]),
        })
    ctx = data.get("context", {})
    print(f"load average {ctx.get('load_avg', '?')}, {ctx.get('num_cpus', '?')} CPUs; "
          "times in ms (CPU time is the steadier figure on a loaded machine)\n")
    print("| method | nx | rtol | CPU ms | wall ms | rel. err S(t0) | max rel. err | steps | RHS | GMRES it. | prec. solves |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        err0 = f"{r['err0']:.2e}" if r["ok"] else "failed"
        errm = f"{r['errmax']:.2e}" if r["ok"] else "failed"
        print(f"| {r['method']} | {r['nx']} | {r['rtol']:.0e} | {r['cpu']:.2f} | {r['wall']:.2f} | "
              f"{err0} | {errm} | {r['steps']} | {r['rhs']} | {r['lin']} | {r['psolve']} |")
    print(f"\nCheapest run (CPU) with relative error of S(t0) <= {args.target:g}:\n")
    print("| method | nx | rtol | CPU ms | rel. err S(t0) | steps |")
    print("|---|---:|---:|---:|---:|---:|")
    keys = sorted({(r["method"], r["nx"]) for r in rows}, key=lambda k: (k[1], k[0]))
    for method, nx in keys:
        good = [r for r in rows if r["method"] == method and r["nx"] == nx and r["ok"]
                and 0 <= r["err0"] <= args.target]
        if not good:
            print(f"| {method} | {nx} | — | — | not reached | — |")
            continue
        best = min(good, key=lambda r: r["cpu"])
        print(f"| {method} | {nx} | {best['rtol']:.0e} | {best['cpu']:.2f} | {best['err0']:.2e} | {best['steps']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
