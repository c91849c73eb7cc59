#!/usr/bin/env python3
"""Turn the Google Benchmark JSON of trellis_bench_core into markdown tables.

Usage: bench_table.py RESULTS.json [--stat min|median|mean] [--time auto|real|cpu]

Prints, in markdown:
  1. one row per model: dynamics, exact linearization and central-difference linearization times,
     the error of each linearization, and the speed-up of the exact one over differences;
  2. the published / measured reference figures (trep, Pinocchio) beside trellis's;
  3. the growth exponent of each time with N for the chains (least squares on log t vs log N);
  4. warnings (failed benchmarks, exact results off their reference, non-repeatable results).
Standard library only.
"""

import argparse
import json
import math
import re
import statistics
import sys

NAME_RE = re.compile(r"^(Dynamics|Linearization|LinearizationFD)/(\w+)/N:(\d+)/nc:(\d+)$")
TO_US = {"ns": 1e-3, "us": 1.0, "ms": 1e3, "s": 1e6}

# (algorithm, model, N, nc, who, what, figure in µs). Figures measured on the same 2-core machine.
REFERENCES = [
    ("Linearization", "planar", 20, 0, "trep", "A, B (planar 20-link chain)", 9.4e3),
    ("Linearization", "planar", 40, 0, "trep", "A, B (planar 40-link chain)", 283e3),
    ("Linearization", "planar", 10, 0, "Pinocchio 3.7", "A, B analytic (planar 10-link)", 8.7),
    ("Linearization", "planar", 20, 0, "Pinocchio 3.7", "A, B analytic (planar 20-link)", 20.0),
    ("Linearization", "planar", 40, 0, "Pinocchio 3.7", "A, B analytic (planar 40-link)", 50.0),
    ("Linearization", "hand", 20, 0, "Pinocchio 3.7", "A, B analytic (20-joint tree)", 17.8),
    ("Linearization", "hand", 20, 3, "Pinocchio 3.7", "A, B analytic (tree + 3D point constraint)", 23.0),
    ("LinearizationFD", "hand", 20, 0, "Pinocchio 3.7", "central FD of forward dynamics (tree)", 812.0),
]

MODEL_ORDER = {"planar": 0, "spatial": 1, "hand": 2}
MODEL_TITLE = {"planar": "planar chain", "spatial": "3D chain", "hand": "hand tree"}


def load_results(path, stat, time_key):
    """Returns {(algo, model, N, nc): {"t": µs, "counters": {...}}} and a list of failures."""
    with open(path, encoding="utf-8") as fh:
        doc = json.load(fh)
    runs, failures = {}, []
    for b in doc.get("benchmarks", []):
        name = b.get("run_name", b["name"])
        m = NAME_RE.match(name)
        if not m:
            continue
        key = (m.group(1), m.group(2), int(m.group(3)), int(m.group(4)))
        if b.get("error_occurred"):
            failures.append(f"{name}: {b.get('error_message', 'error')}")
            continue
        if b.get("run_type", "iteration") != "iteration":
            continue  # aggregates are recomputed below from the repetitions
        entry = runs.setdefault(key, {"times": [], "counters": {}})
        entry["times"].append(b[time_key] * TO_US[b.get("time_unit", "ns")])
        for k, v in b.items():
            if isinstance(v, (int, float)) and k not in (
                "real_time", "cpu_time", "iterations", "repetitions", "repetition_index",
                "threads", "family_index", "per_family_instance_index"):
                entry["counters"][k] = v
    pick = {"min": min, "median": statistics.median, "mean": statistics.fmean}[stat]
    out = {k: {"t": pick(v["times"]), "n": len(v["times"]), "counters": v["counters"]}
           for k, v in runs.items()}
    return doc.get("context", {}), out, failures


def fmt_time(us):
    if us is None:
        return "–"
    if us >= 1e5:
        return f"{us / 1e3:.0f} ms"
    if us >= 1e4:
        return f"{us / 1e3:.1f} ms"
    if us >= 1e3:
        return f"{us / 1e3:.2f} ms"
    if us >= 100:
        return f"{us:.0f}"
    if us >= 10:
        return f"{us:.1f}"
    return f"{us:.2f}"


def fmt_load(load):
    return "?" if not load else ", ".join(f"{x:.1f}" for x in load)


def fmt_err(e):
    return "–" if e is None else f"{e:.1e}"


def fmt_exact_err(run):
    """The exact result's error against the reference, with the reference's own error."""
    if run is None or "ref_err" not in run["counters"]:
        return "–"
    c = run["counters"]
    unc = c.get("ref_unc")
    return fmt_err(c["ref_err"]) + ("" if unc is None else f" (±{unc:.0e})")


def fmt_ratio(r):
    if r is None:
        return "–"
    return f"{r:.0f}×" if r >= 10 else f"{r:.1f}×"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", help="JSON written by --benchmark_out")
    ap.add_argument("--stat", choices=["min", "median", "mean"], default="min",
                    help="statistic over repetitions (default: min, the least disturbed run)")
    ap.add_argument("--time", choices=["auto", "real", "cpu"], default="auto",
                    help="wall or CPU time; auto (default): wall time unless the load average "
                         "recorded with the results exceeds half the CPUs, then CPU time")
    args = ap.parse_args()

    with open(args.results, encoding="utf-8") as fh:
        ctx = json.load(fh).get("context", {})
    busy = (ctx.get("load_avg") or [0.0])[0] > 0.5 * (ctx.get("num_cpus") or 1)
    if args.time == "auto":
        args.time = "cpu" if busy else "real"
    context, runs, failures = load_results(args.results, args.stat, f"{args.time}_time")
    if not runs:
        print(f"no trellis benchmark results in {args.results}", file=sys.stderr)
        return 1

    def get(algo, model, n, nc):
        return runs.get((algo, model, n, nc))

    def t(algo, model, n, nc):
        r = get(algo, model, n, nc)
        return None if r is None else r["t"]

    def counter(algo, model, n, nc, name):
        r = get(algo, model, n, nc)
        return None if r is None else r["counters"].get(name)

    cases = sorted({(k[1], k[2], k[3]) for k in runs},
                   key=lambda c: (MODEL_ORDER.get(c[0], 9), c[2], c[1]))
    reps = max(r["n"] for r in runs.values())
    print(f"Times in µs unless marked ({args.stat} of {reps} repetition(s), {args.time} time; "
          f"{context.get('num_cpus', '?')} CPUs @ {context.get('mhz_per_cpu', '?')} MHz, "
          f"load average {fmt_load(context.get('load_avg'))}).")
    print()
    if busy:
        print(f"**The machine was busy (load {context['load_avg'][0]:.1f} on {context.get('num_cpus')} "
              f"CPUs): wall times are inflated{'; CPU times shown' if args.time == 'cpu' else ''}. "
              "Re-run on a quiet machine for figures comparable to the references.**")
        print()
    print("Errors are max|J − ref| / max(1, max|ref|) over J = ∂q̈/∂[q; q̇; u]: the exact result "
          "against a Richardson-extrapolated reference (± that reference's own error, from a second "
          "step size), the central differences against the exact result; \"col err\" is the same "
          "measure for the worst single column.")
    print()
    print("| model | N | nq | nc | dynamics | exact lin. | exact err | FD lin. | FD err | FD col err | "
          "FD / exact | reference (exact lin.) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for model, n, nc in cases:
        tdyn, tlin, tfd = (t(a, model, n, nc) for a in ("Dynamics", "Linearization", "LinearizationFD"))
        nq = next((int(r["counters"]["nq"]) for a in ("Dynamics", "Linearization", "LinearizationFD")
                   if (r := get(a, model, n, nc)) and "nq" in r["counters"]), n)
        refs = [f"{who} {fmt_time(fig)}{'' if fig >= 1e3 else ' µs'}"
                for algo, rm, rn, rnc, who, _, fig in REFERENCES
                if algo == "Linearization" and (rm, rn, rnc) == (model, n, nc)]
        print(f"| {MODEL_TITLE.get(model, model)} | {n} | {nq} | {nc} | {fmt_time(tdyn)} | "
              f"{fmt_time(tlin)} | {fmt_exact_err(get('Linearization', model, n, nc))} | "
              f"{fmt_time(tfd)} | {fmt_err(counter('LinearizationFD', model, n, nc, 'max_rel_err'))} | "
              f"{fmt_err(counter('LinearizationFD', model, n, nc, 'col_rel_err'))} | "
              f"{fmt_ratio(tfd / tlin if tfd and tlin else None)} | {'; '.join(refs) or ''} |")

    print()
    print("Reference figures (same machine) against trellis; ratio = trellis time / reference time "
          "(below 1: trellis is faster).")
    print()
    print("| reference | what | figure | trellis | ratio |")
    print("|---|---|---:|---:|---:|")
    for algo, model, n, nc, who, what, fig in REFERENCES:
        mine = t(algo, model, n, nc)
        if mine is None:
            continue  # not in this run (--benchmark_filter)
        label = "exact" if algo == "Linearization" else "FD"
        print(f"| {who} | {what} | {fmt_time(fig)}{'' if fig >= 1e3 else ' µs'} | "
              f"{fmt_time(mine)}{'' if mine is None or mine >= 1e3 else ' µs'} ({label}) | "
              f"{'–' if mine is None else f'{mine / fig:.3g}'} |")

    growth = [(model, nc) for model in ("planar", "spatial")
              for nc in sorted({c[2] for c in cases if c[0] == model})
              if sum(1 for c in cases if c[0] == model and c[2] == nc and c[1] >= 10) >= 2]
    if growth:
        print()
        print("Growth with N for the chains: exponent p of t ≈ c·N^p, least squares over N ≥ 10.")
        print()
        print("| model | nc | dynamics | exact lin. | FD lin. |")
        print("|---|---:|---:|---:|---:|")
    for model, nc in growth:
        cells = []
        for algo in ("Dynamics", "Linearization", "LinearizationFD"):
            pts = [(math.log(c[1]), math.log(t(algo, model, c[1], nc)))
                   for c in cases if c[0] == model and c[2] == nc and c[1] >= 10
                   and t(algo, model, c[1], nc)]
            if len(pts) < 2:
                cells.append("–")
                continue
            mx = sum(p[0] for p in pts) / len(pts)
            my = sum(p[1] for p in pts) / len(pts)
            sxx = sum((p[0] - mx) ** 2 for p in pts)
            sxy = sum((p[0] - mx) * (p[1] - my) for p in pts)
            cells.append(f"{sxy / sxx:.2f}")
        print(f"| {MODEL_TITLE[model]} | {nc} | " + " | ".join(cells) + " |")

    warnings = list(failures)
    for (algo, model, n, nc), r in sorted(runs.items()):
        c = r["counters"]
        if algo == "Linearization" and c.get("ref_err", 0.0) > max(1e-9, 10.0 * c.get("ref_unc", 0.0)):
            warnings.append(f"{algo}/{model}/N:{n}/nc:{nc}: exact result is {c['ref_err']:.1e} "
                            f"from the Richardson reference, whose own error is about "
                            f"{c.get('ref_unc', float('nan')):.1e}")
        if algo == "Linearization" and c.get("ref_col_err", 0.0) > max(1e-9, 10.0 * c.get("ref_col_unc", 0.0)):
            warnings.append(f"{algo}/{model}/N:{n}/nc:{nc}: the worst column of the exact result is "
                            f"{c['ref_col_err']:.1e} from the reference, whose own error there is about "
                            f"{c.get('ref_col_unc', float('nan')):.1e}")
        if algo == "Linearization" and c.get("repeat_diff", 0.0) != 0.0:
            warnings.append(f"{algo}/{model}/N:{n}/nc:{nc}: repeated evaluation at the same state "
                            f"changed the result by {c['repeat_diff']:.1e}")
        if algo == "LinearizationFD" and c.get("max_rel_err", 0.0) > 1e-5:
            warnings.append(f"{algo}/{model}/N:{n}/nc:{nc}: differences are {c['max_rel_err']:.1e} "
                            "from the exact result (expected ~1e-9)")
    if warnings:
        print()
        print("Warnings:")
        print()
        for w in warnings:
            print(f"- {w}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
