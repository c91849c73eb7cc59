#!/usr/bin/env python3
"""Write docs/performance.md and its PNG plots from the JSON of the trellis benchmarks.

    perf_report.py --results DIR --md FILE --figures DIR [--build-dir DIR]
                   [--hand-summary FILE] [--mode full|fast] [--command TEXT]

DIR (--results) holds what scripts/perf_report.sh left there, one pair per benchmark program:
  <name>.json     Google Benchmark JSON (--benchmark_out_format=json, with repetitions)
  <name>.status   one line: "ok", or why the program was not run / failed
for <name> in linearization_sweep (required), riccati and optimization (optional: a missing one
becomes a note in its section). Sections and plots:
  1. linearization time against the number of bodies, log-log, exact / central / forward FD,
     with the growth exponent of each method fitted on the chains (least squares on
     log t = a + p log N over N >= 8, where the fixed per-call costs no longer dominate);
  2. linearization error against time, one point per finite-difference step, the exact method
     at its error floor;
  3. Riccati error against time over the tolerance sweep, per method and state size;
  4. trajectory optimization solve time and Ipopt iterations against knots, exact vs FD;
  5. the hand's main job, time per stage (parsed from output/hand/summary.txt when present).
The machine (CPU model, cores, compiler and flags from the build directory's CMakeCache.txt),
the date and the load average (from each program's Google Benchmark context) head the report.
Timings are the median over repetitions with the spread (min–max over repetitions); when the
load average exceeded half the cores the CPU time is reported instead of the wall time (the
machine is shared: CPU time excludes the waiting, not the cache pollution).

Exit status: 0 when the report was written and every program that ran succeeded; 1 when a
program failed or a benchmark reported an error (the report is still written, with the
failures listed); 2 when the report cannot be generated (bad input, matplotlib missing).
Uses matplotlib's Agg backend (Debian's python3-matplotlib).
"""
import argparse
import datetime
import json
import math
import os
import platform
import re
import statistics
import subprocess
import sys

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: E402
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    sys.exit(f"perf_report.py: matplotlib is required ({exc}); use Debian's /usr/bin/python3 "
             "with python3-matplotlib")

TO_US = {"ns": 1e-3, "us": 1.0, "ms": 1e3, "s": 1e6}
METHODS = ["exact", "central", "forward"]
METHOD_STYLE = {"exact": ("tab:blue", "o"), "central": ("tab:orange", "s"),
                "forward": ("tab:green", "^")}
FAMILY_TITLE = {"planar": "planar chain", "spatial": "3D chain", "hand": "hand tree (20 joints)"}
FIGURES = ("linearization_scaling.png", "linearization_error_vs_time.png", "riccati_error_vs_time.png",
           "optimization_vs_knots.png", "hand_main_job_stages.png")
FIT_MIN_N = 8
RICCATI_TARGET = 1e-6  # the accuracy at which the Riccati methods' speeds are compared
ERR_FLOOR = 1e-17  # plotted in place of an error of exactly 0 (log axes)


class ReportError(Exception):
    """The input cannot be turned into a report."""


# ---- Reading ----------------------------------------------------------------------------------

class Program:
    """One benchmark program's results: {run_name: Run}, its context, status and failures."""

    def __init__(self, name, results_dir):
        self.name = name
        self.status = "not run (no result in the results folder)"
        self.context = {}
        self.runs = {}
        self.failures = []
        status_path = os.path.join(results_dir, name + ".status")
        json_path = os.path.join(results_dir, name + ".json")
        if os.path.exists(status_path):
            with open(status_path, encoding="utf-8") as fh:
                self.status = fh.read().strip() or "not run"
        self.command = ""
        args_path = os.path.join(results_dir, name + ".args")
        if os.path.exists(args_path):
            with open(args_path, encoding="utf-8") as fh:
                self.command = fh.read().strip()
        if self.status != "ok":
            return
        try:
            with open(json_path, encoding="utf-8") as fh:
                doc = json.load(fh, object_pairs_hook=keep_duplicate_keys)
        except (OSError, ValueError) as exc:
            raise ReportError(f"{json_path}: {exc}") from exc
        self.context = doc.get("context", {})
        for b in doc.get("benchmarks", []):
            name_ = b.get("run_name", b.get("name", "?"))
            if b.get("error_occurred"):
                self.failures.append(f"{name_}: {b.get('error_message', 'error')}")
                continue
            run = self.runs.setdefault(name_, Run(name_))
            run.add(b)

    @property
    def ok(self):
        return self.status == "ok"


def keep_duplicate_keys(pairs):
    """A JSON object as a dict, where a key seen twice keeps both values: the second as
    "counter:<key>". Google Benchmark writes user counters beside its own fields, so a counter
    named like a field (optimization_bench's "iterations", Ipopt's) duplicates that key."""
    out = {}
    for k, v in pairs:
        out["counter:" + k if k in out else k] = v
    return out


class Run:
    """Repetitions of one benchmark: times in µs (real and CPU), counters, GB's aggregates."""

    def __init__(self, name):
        self.name = name
        self.real, self.cpu = [], []
        self.counters = {}
        self.aggregates = {}
        self.label = ""

    def add(self, b):
        unit = TO_US[b.get("time_unit", "ns")]
        if b.get("run_type", "iteration") == "aggregate":
            self.aggregates[b.get("aggregate_name", "?")] = (b["real_time"] * unit, b["cpu_time"] * unit)
            return
        self.real.append(b["real_time"] * unit)
        self.cpu.append(b["cpu_time"] * unit)
        self.label = b.get("label", self.label)
        skip = {"real_time", "cpu_time", "iterations", "repetitions", "repetition_index", "threads",
                "family_index", "per_family_instance_index"}
        for k, v in b.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool) and k not in skip:
                self.counters.setdefault(k, []).append(float(v))

    def time(self, use_cpu):
        """(median, min, max) in µs over the repetitions."""
        xs = self.cpu if use_cpu else self.real
        return statistics.median(xs), min(xs), max(xs)

    def counter(self, key, default=None):
        xs = self.counters.get(key)
        return statistics.median(xs) if xs else default


def machine_info(build_dir):
    """CPU model, cores, compiler and flags (from the build directory when given)."""
    info = {"cpu": "unknown", "cores": os.cpu_count() or 0, "compiler": "unknown",
            "flags": "unknown", "build_type": "unknown", "os": platform.platform()}
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    cache = {}
    if build_dir:
        try:
            with open(os.path.join(build_dir, "CMakeCache.txt"), encoding="utf-8") as fh:
                for line in fh:
                    m = re.match(r"^([A-Za-z_]+):[A-Z]+=(.*)$", line.strip())
                    if m:
                        cache[m.group(1)] = m.group(2)
        except OSError:
            pass
    compiler = cache.get("CMAKE_CXX_COMPILER", "c++")
    try:
        out = subprocess.run([compiler, "--version"], capture_output=True, text=True, timeout=10)
        info["compiler"] = out.stdout.splitlines()[0].strip() if out.stdout else compiler
    except (OSError, subprocess.SubprocessError):
        info["compiler"] = compiler
    build_type = cache.get("CMAKE_BUILD_TYPE", "")
    if build_type:
        info["build_type"] = build_type
        flags = " ".join(x for x in (cache.get("CMAKE_CXX_FLAGS", ""),
                                     cache.get(f"CMAKE_CXX_FLAGS_{build_type.upper()}", "")) if x)
        info["flags"] = (flags + " -Wall -Wextra -Wpedantic").strip()
    return info


def parse_hand_summary(path):
    """[(stage, seconds)] and the whole-job time from hand_main_job's summary.txt, or None."""
    if not path or not os.path.exists(path):
        return None
    stages, total = [], None
    in_table = False
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            if re.match(r"^\s*stage\s+time \[s\]\s*$", line):
                in_table = True
                continue
            if in_table:
                m = re.match(r"^\s{2}(\S.*?)\s+(-?\d+(?:\.\d+)?)\s*$", line)
                if not m:
                    break
                if m.group(1) == "whole job":
                    total = float(m.group(2))
                else:
                    stages.append((m.group(1), float(m.group(2))))
    if not stages:
        raise ReportError(f"{path}: no stage table (expected a 'stage ... time [s]' header)")
    return stages, total


# ---- Formatting and fitting -------------------------------------------------------------------

def fmt_us(us):
    if us is None or not math.isfinite(us):
        return "–"
    if us >= 1e6:
        return f"{us / 1e6:.2f} s"
    if us >= 1e3:
        return f"{us / 1e3:.3g} ms"
    return f"{us:.3g} µs"


def fmt_spread(t):
    """Median ± the largest deviation of a repetition from it, in per cent."""
    med, lo, hi = t
    dev = max(hi - med, med - lo) / med * 100 if med > 0 else 0.0
    return f"{fmt_us(med)} ±{dev:.0f}%" if hi > lo else fmt_us(med)


def fmt_err(e):
    if e is None:
        return "–"
    return "0" if e == 0 else f"{e:.1e}"


def fit_exponent(ns, ts, with_error=False):
    """Least-squares slope p of log t = a + p log N (None with fewer than two points); with
    with_error, (p, its standard error sqrt(SSE / (k − 2) / Sxx), None for k ≤ 2 points)."""
    pts = [(math.log(n), math.log(t)) for n, t in zip(ns, ts) if t > 0]
    mx = statistics.fmean(x for x, _ in pts) if pts else 0.0
    my = statistics.fmean(y for _, y in pts) if pts else 0.0
    sxx = sum((x - mx) ** 2 for x, _ in pts)
    if len(pts) < 2 or sxx <= 0:
        return (None, None) if with_error else None
    p = sum((x - mx) * (y - my) for x, y in pts) / sxx
    if not with_error:
        return p
    if len(pts) < 3:
        return p, None
    sse = sum((y - my - p * (x - mx)) ** 2 for x, y in pts)
    return p, math.sqrt(sse / (len(pts) - 2) / sxx)


def fmt_exponent(p, err):
    if p is None:
        return "–"
    return f"{p:.2f}" + (f" ± {err:.2f}" if err is not None else "")


def md_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


# ---- Sections ---------------------------------------------------------------------------------

SCALING_RE = re.compile(r"^Scaling/(exact|central|forward)/(\w+)/N:(\d+)/nc:(\d+)$")
ACCURACY_RE = re.compile(r"^Accuracy/(central|forward)/(\w+)/N:(\d+)/nc:(\d+)/h:(\d+)$")


def section_scaling(prog, use_cpu, fig_dir, rel, out):
    """Plot 1 and the exponents. Returns the markdown."""
    cases = {}  # (family, nc) -> {method: {N: Run}}
    for name, run in prog.runs.items():
        m = SCALING_RE.match(name)
        if m:
            method, family, n, nc = m.group(1), m.group(2), int(m.group(3)), int(m.group(4))
            cases.setdefault((family, nc), {}).setdefault(method, {})[n] = run
    if not cases:
        return "No `Scaling/...` results in the linearization sweep.\n"

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    exponents = []
    for (family, nc), by_method in sorted(cases.items()):
        if family == "hand":
            continue
        ax = axes[0] if family == "planar" else axes[1]
        for method in METHODS:
            runs = by_method.get(method, {})
            ns = sorted(runs)
            if not ns:
                continue
            ts = [runs[n].time(use_cpu)[0] for n in ns]
            lo = [ts[i] - runs[n].time(use_cpu)[1] for i, n in enumerate(ns)]
            hi = [runs[n].time(use_cpu)[2] - ts[i] for i, n in enumerate(ns)]
            color, marker = METHOD_STYLE[method]
            ax.errorbar(ns, ts, yerr=[lo, hi], color=color, marker=marker, ms=4, capsize=2,
                        linestyle="-" if nc == 0 else "--",
                        label=("3D chain, " if family == "spatial" else "") + method
                        + (f", {nc} constraint row{'s' * (nc > 1)}" if nc else ""))
            fit_ns = [n for n in ns if n >= FIT_MIN_N]
            p, p_err = fit_exponent(fit_ns, [runs[n].time(use_cpu)[0] for n in fit_ns], with_error=True)
            p_all = fit_exponent(ns, ts)
            exponents.append((FAMILY_TITLE.get(family, family), nc, method, (p, p_err), p_all,
                              f"{fit_ns[0]}–{fit_ns[-1]}" if fit_ns else "–"))
    hand = cases.get(("hand", 0), {}), cases.get(("hand", 3), {})
    for nc, by_method in zip((0, 3), hand):
        for method in METHODS:
            run = by_method.get(method, {}).get(20)
            if run is None:
                continue
            color, _ = METHOD_STYLE[method]
            axes[1].plot([20], [run.time(use_cpu)[0]], linestyle="none", color=color,
                         marker="*" if nc == 0 else "D", ms=11 if nc == 0 else 7,
                         markeredgecolor="black",
                         label=f"hand tree, {method}" + (" + 3D point constraint" if nc else ""))
    for ax, title in zip(axes, ("planar chains", "3D chains and the 20-joint hand tree")):
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("number of bodies N")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel(f"time per linearization [µs] ({'CPU' if use_cpu else 'wall'})")
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "linearization_scaling.png"), dpi=110)
    plt.close(fig)

    md = [f"![linearization time against N]({rel}/linearization_scaling.png)\n",
          f"Growth exponent p of the time t ∝ N^p, least squares on log t against log N over N ≥ "
          f"{FIT_MIN_N} (below that, fixed per-call costs dominate; the fit over every N is given "
          "beside it):\n",
          md_table(["model", "constraint rows", "method", f"p (N ≥ {FIT_MIN_N})", "p (all N)", "N fitted"],
                   [(f, nc, m, fmt_exponent(*p), "–" if pa is None else f"{pa:.2f}", rng)
                    for f, nc, m, p, pa, rng in exponents]),
          "",
          "(± is the standard error of the fitted slope: the scatter of the points about the "
          "straight line, which includes the timing noise of a shared machine.)",
          "",
          "Times (median over repetitions ± the largest deviation of one) and errors; `err` is "
          "max|J − J_ref| / max(1, max|J_ref|) over J = ∂q̈/∂[q; q̇; u], against the exact result for "
          "the finite differences and against a two-level Richardson reference for the exact method "
          "(whose own uncertainty is the last column):\n"]
    rows = []
    for (family, nc), by_method in sorted(cases.items(), key=lambda kv: ({"planar": 0, "spatial": 1}.get(kv[0][0], 2), kv[0][1])):
        ns = sorted(set().union(*[set(v) for v in by_method.values()]))
        for n in ns:
            row = [FAMILY_TITLE.get(family, family), n, nc]
            exact = by_method.get("exact", {}).get(n)
            for method in METHODS:
                run = by_method.get(method, {}).get(n)
                row.append(fmt_spread(run.time(use_cpu)) if run else "–")
            for method in METHODS:
                run = by_method.get(method, {}).get(n)
                row.append(fmt_err(run.counter("err")) if run else "–")
            central = by_method.get("central", {}).get(n)
            row.append(f"{central.time(use_cpu)[0] / exact.time(use_cpu)[0]:.1f}×" if exact and central else "–")
            row.append(fmt_err(exact.counter("ref_unc")) if exact else "–")
            rows.append(row)
    md.append(md_table(["model", "N", "nc", "exact", "central FD", "forward FD", "err exact",
                        "err central", "err forward", "central / exact", "ref. uncertainty"], rows))
    out["exponents"] = exponents
    out["scaling_cases"] = cases
    return "\n".join(md) + "\n"


def section_accuracy(prog, use_cpu, fig_dir, rel, out):
    """Plot 2: error against time, one point per step. Returns the markdown."""
    pts = {}  # (family, N, nc) -> {method: [(k, Run)]}
    for name, run in prog.runs.items():
        m = ACCURACY_RE.match(name)
        if m:
            key = (m.group(2), int(m.group(3)), int(m.group(4)))
            pts.setdefault(key, {}).setdefault(m.group(1), []).append((int(m.group(5)), run))
    if not pts:
        return "No `Accuracy/...` results in the linearization sweep.\n"
    cases = out.get("scaling_cases", {})
    keys = sorted(pts, key=lambda k: ({"planar": 0, "spatial": 1}.get(k[0], 2), k[1], k[2]))
    fig, axes = plt.subplots(1, len(keys), figsize=(4.4 * len(keys), 4.4), squeeze=False)
    rows = []
    for ax, key in zip(axes[0], keys):
        family, n, nc = key
        for method in ("central", "forward"):
            series = sorted(pts[key].get(method, []))
            if not series:
                continue
            ts = [r.time(use_cpu)[0] for _, r in series]
            es = [max(r.counter("err", 0.0), ERR_FLOOR) for _, r in series]
            color, marker = METHOD_STYLE[method]
            ax.plot(ts, es, color=color, marker=marker, linestyle="none", label=f"{method} FD")
            for (k, _), t, e in zip(series, ts, es):
                ax.annotate(f"1e-{k}", (t, e), fontsize=6, xytext=(3, 0), textcoords="offset points")
            best = min(series, key=lambda kr: kr[1].counter("err", math.inf))
            rows.append((FAMILY_TITLE.get(family, family), n, nc, f"{method} FD",
                         f"1e-{best[0]}", fmt_us(best[1].time(use_cpu)[0]), fmt_err(best[1].counter("err"))))
        exact = cases.get((family, nc), {}).get("exact", {}).get(n)
        if exact is not None:
            e, unc = exact.counter("err", 0.0), exact.counter("ref_unc", 0.0)
            t = exact.time(use_cpu)[0]
            color, marker = METHOD_STYLE["exact"]
            ax.plot([t], [max(e, ERR_FLOOR)], color=color, marker=marker, ms=9, linestyle="none",
                    markeredgecolor="black", label="exact (vs reference)")
            if unc > 0:
                ax.axhline(unc, color="gray", linestyle=":", linewidth=1, label="reference uncertainty")
            rows.append((FAMILY_TITLE.get(family, family), n, nc, "exact", "–", fmt_us(t),
                         f"{fmt_err(e)} (reference ±{fmt_err(unc)})"))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"time per linearization [µs] ({'CPU' if use_cpu else 'wall'})")
        ax.set_title(f"{FAMILY_TITLE.get(family, family)}, N = {n}" + (f", {nc} constraint rows" if nc else ""),
                     fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("max relative error of ∂q̈/∂[q; q̇; u]")
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "linearization_error_vs_time.png"), dpi=110)
    plt.close(fig)
    md = [f"![linearization error against time]({rel}/linearization_error_vs_time.png)\n",
          "Each finite-difference point is one step h = 10⁻² … 10⁻¹⁰ (relative: h·max(1, |z_j|)); "
          "the exact method is one point, its error measured against a reference of two Richardson "
          "levels on central differences, (64 D(h/4) − 20 D(h/2) + D(h))/45 at h = ε^(1/7) "
          "(truncation O(h⁶), rounding O(ε/h)); the dotted line is that reference's own uncertainty "
          "(the difference between the reference at h and at 2h), so the exact error is resolved "
          "only down to it. Best step of each method:\n",
          md_table(["model", "N", "nc", "method", "best step", "time", "error"], rows)]
    return "\n".join(md) + "\n"


RICCATI_RE = re.compile(r"^BM_Riccati/n:(\d+)/method:(\d+)/tol:(\d+)")


def section_riccati(prog, use_cpu, fig_dir, rel):
    groups = {}  # nx -> {label: [(rtol, Run)]}
    for name, run in prog.runs.items():
        m = RICCATI_RE.match(name)
        if not m:
            continue
        nx = int(run.counter("nx", 2 * int(m.group(1))))
        label = run.label or f"method {m.group(2)}"
        groups.setdefault(nx, {}).setdefault(label, []).append((run.counter("rtol", 10.0 ** -int(m.group(3))), run))
    if not groups:
        return "The Riccati benchmark produced no `BM_Riccati/n:…/method:…/tol:…` results.\n"
    nxs = sorted(groups)
    ncols = min(len(nxs), 2)
    nrows = math.ceil(len(nxs) / ncols)
    fig, grid = plt.subplots(nrows, ncols, figsize=(5.5 * ncols, 4.2 * nrows), squeeze=False)
    axes = [[ax for row in grid for ax in row]]
    for ax in axes[0][len(nxs):]:
        ax.set_visible(False)
    labels = sorted({lbl for g in groups.values() for lbl in g})
    colors = {lbl: f"C{i}" for i, lbl in enumerate(labels)}
    rows, failed = [], []
    for ax, nx in zip(axes[0], nxs):
        for label in labels:
            series = sorted(groups[nx].get(label, []), key=lambda x: -x[0])
            good = [(tol, r) for tol, r in series if r.counter("ok", 1) == 1 and r.counter("max_rel_err", -1) >= 0]
            failed += [f"nx = {nx}, {label}, rtol {tol:.0e}" for tol, r in series if (tol, r) not in good]
            if not good:
                continue
            ts = [r.time(use_cpu)[0] / 1e3 for _, r in good]
            es = [max(r.counter("max_rel_err"), ERR_FLOOR) for _, r in good]
            ax.plot(ts, es, marker="o", ms=3, color=colors[label], label=label)
            for tol, r in good:
                rows.append((nx, label, f"{tol:.0e}", fmt_spread(r.time(use_cpu)),
                             fmt_err(r.counter("max_rel_err")), f"{r.counter('steps', 0):.0f}"))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"nx = {nx}", fontsize=9)
        ax.set_xlabel(f"solve time [ms] ({'CPU' if use_cpu else 'wall'})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
    for row in grid:
        row[0].set_ylabel("max relative error of S(t) (21 times)")
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "riccati_error_vs_time.png"), dpi=110)
    plt.close(fig)
    # Speed at a given accuracy: per state size, the cheapest solve of each method whose error is
    # at most RICCATI_TARGET.
    target_lines = []
    for nx in nxs:
        best = []
        for label in labels:
            ok_pts = [r.time(use_cpu)[0] for _, r in groups[nx].get(label, [])
                      if r.counter("ok", 1) == 1 and 0 <= r.counter("max_rel_err", -1) <= RICCATI_TARGET]
            if ok_pts:
                best.append((min(ok_pts), label))
        if best:
            best.sort()
            target_lines.append(f"- nx = {nx}: " + ", ".join(f"{lbl} {fmt_us(t)}" for t, lbl in best))
    md = [f"![Riccati error against time]({rel}/riccati_error_vs_time.png)\n",
          "Each line is one method over the tolerance sweep (rtol = 10⁻³ … 10⁻¹⁰, atol = rtol·10⁻²); "
          "the error is max over 21 times of |S − S_ref| / max|S_ref| against a BDF solve at rtol 10⁻¹³ "
          "(see bench/riccati_bench.cpp for the system: blended exact linearizations of the planar chain).\n"]
    if target_lines:
        md += [f"Cheapest solve reaching an error ≤ {RICCATI_TARGET:.0e}, per state size (fastest first):\n",
               "\n".join(target_lines), ""]
    md += ["<details><summary>Every solve of the sweep</summary>\n",
           md_table(["nx", "method", "rtol", "time", "error", "steps"], rows), "\n</details>"]
    if failed:
        md.append("\nSolves that did not succeed (not plotted): " + "; ".join(failed) + ".")
    return "\n".join(md) + "\n"


OPT_RE = re.compile(r"^solve/problem:(\d+)/knots:(\d+)/fd:(\d+)")


def section_optimization(prog, use_cpu, fig_dir, rel):
    series = {}  # (problem, fd) -> [(knots, Run)]
    for name, run in prog.runs.items():
        m = OPT_RE.match(name)
        if m:
            problem = (run.label or f"problem {m.group(1)}").replace(" exact", "").replace(" finite-difference", "")
            series.setdefault((problem, int(m.group(3))), []).append((int(m.group(2)), run))
    if not series:
        return "The optimization benchmark produced no `solve/problem:…/knots:…/fd:…` results.\n"

    def ipopt_iterations(run):
        return run.counter("ipopt_iterations", run.counter("counter:iterations", math.nan))

    def solve_times_us(run):
        # cpu_ms: the process CPU time of one solve (the benchmark itself times the wall clock).
        if use_cpu and run.counters.get("cpu_ms"):
            return [1e3 * x for x in run.counters["cpu_ms"]]
        return run.real

    def seconds(run):
        return statistics.median(solve_times_us(run)) / 1e6

    def spread(run):
        xs = solve_times_us(run)
        return fmt_spread((statistics.median(xs), min(xs), max(xs)))

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    problems = sorted({p for p, _ in series})
    rows = []
    for i, problem in enumerate(problems):
        for fd in (0, 1):
            pts = sorted(series.get((problem, fd), []))
            if not pts:
                continue
            ks = [k for k, _ in pts]
            style = dict(color=f"C{i}", marker="o" if fd == 0 else "s", linestyle="-" if fd == 0 else "--",
                         label=f"{problem}, {'finite-difference' if fd else 'exact'} Jacobian")
            axes[0].plot(ks, [seconds(r) for _, r in pts], **style)
            axes[1].plot(ks, [ipopt_iterations(r) for _, r in pts], **style)
            for k, r in pts:
                rows.append((problem, k, "FD" if fd else "exact", spread(r),
                             f"{ipopt_iterations(r):.0f}",
                             "yes" if r.counter("success", 0) == 1 else "**no**",
                             f"{r.counter('cost', math.nan):.6g}", fmt_err(r.counter("viol"))))
    axes[0].set_yscale("log")
    axes[0].set_ylabel(f"solve time [s] ({'CPU' if use_cpu else 'wall'})")
    axes[1].set_ylabel("Ipopt iterations")
    all_knots = sorted({k for pts in series.values() for k, _ in pts})
    for ax in axes:
        ax.set_xscale("log", base=2)
        ax.set_xticks(all_knots, [str(k) for k in all_knots])
        ax.minorticks_off()
        ax.set_xlabel("knots")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "optimization_vs_knots.png"), dpi=110)
    plt.close(fig)
    md = [f"![trajectory optimization against knots]({rel}/optimization_vs_knots.png)\n",
          "Ipopt on the swing-ups of examples/problems/ (Hermite–Simpson collocation), the constraint "
          "Jacobian exact (the core's linearization) or by central differences of the dynamics; "
          "time per solve (each repetition is the mean of 3 solves; median over the repetitions ± the largest "
          "deviation of one):\n",
          md_table(["problem", "knots", "Jacobian", "time", "iterations", "converged", "cost",
                    "max defect"], rows)]
    return "\n".join(md) + "\n"


def display_path(path):
    """path relative to the repository when inside it (the report must not name a home directory)."""
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    full = os.path.abspath(path)
    return os.path.relpath(full, repo) if full.startswith(repo + os.sep) else path


def run_line(prog):
    """How the program was run (filter, repetitions, minimum time), for the section's end."""
    return f"\nRun: `{prog.command}`.\n" if prog.command else ""


def section_hand(summary, path, fig_dir, rel):
    stages, total = summary
    fig, ax = plt.subplots(figsize=(9, 0.45 * len(stages) + 1.5))
    names = [s for s, _ in stages][::-1]
    secs = [t for _, t in stages][::-1]
    ax.barh(names, secs, color="tab:blue")
    for y, t in enumerate(secs):
        ax.annotate(f"{t:.3g} s", (t, y), xytext=(3, -3), textcoords="offset points", fontsize=7)
    ax.set_xlabel("wall time [s]")
    ax.set_title("hand main job: time per stage" + (f" (whole job {total:.3g} s)" if total else ""))
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, "hand_main_job_stages.png"), dpi=110)
    plt.close(fig)
    rows = [(s, f"{t:.3f}") for s, t in stages]
    if total is not None:
        rows.append(("**whole job**", f"**{total:.3f}**"))
    return (f"![hand main job stages]({rel}/hand_main_job_stages.png)\n\n"
            f"From `{display_path(path)}` (written by examples/main_job/hand_main_job; file dated "
            f"{datetime.datetime.fromtimestamp(os.path.getmtime(path), datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, "
            "one run, wall time):\n\n" + md_table(["stage", "time [s]"], rows) + "\n")


# ---- Main -------------------------------------------------------------------------------------

# The report is regenerated whole, except what follows this line in the existing file: the
# measurements taken by hand (comparisons, history) that no benchmark program reproduces.
KEPT_MARKER = "<!-- Everything below this line is written by hand; bench/perf_report.py keeps it. -->"


def kept_section(path):
    """The hand-written tail of an existing report, from KEPT_MARKER on ("" when there is none)."""
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except FileNotFoundError:
        return ""
    at = text.find(KEPT_MARKER)
    return text[at:] if at >= 0 else ""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", required=True, help="directory with <program>.json / .status")
    ap.add_argument("--md", required=True, help="markdown report to write")
    ap.add_argument("--figures", required=True, help="directory for the PNG plots")
    ap.add_argument("--build-dir", default=None, help="build directory (CMakeCache.txt: compiler, flags)")
    ap.add_argument("--hand-summary", default=None, help="hand_main_job's summary.txt")
    ap.add_argument("--mode", choices=("full", "fast"), default="full")
    ap.add_argument("--command", default="scripts/perf_report.sh", help="command line shown in the report")
    args = ap.parse_args(argv)

    try:
        return write_report(args)
    except ReportError as exc:
        print(f"perf_report.py: {exc}", file=sys.stderr)
        return 2


def write_report(args):
    programs = {name: Program(name, args.results) for name in ("linearization_sweep", "riccati", "optimization")}
    sweep = programs["linearization_sweep"]
    if not sweep.ok:
        raise ReportError(f"the linearization sweep is required and did not run: {sweep.status}")
    if not sweep.runs:
        raise ReportError("the linearization sweep's JSON has no results")
    os.makedirs(args.figures, exist_ok=True)
    # A section skipped this time must not leave the previous run's plot behind.
    for png in FIGURES:
        if os.path.exists(os.path.join(args.figures, png)):
            os.remove(os.path.join(args.figures, png))
    md_dir = os.path.dirname(os.path.abspath(args.md))
    os.makedirs(md_dir, exist_ok=True)
    rel = os.path.relpath(os.path.abspath(args.figures), md_dir)

    info = machine_info(args.build_dir)
    cores = info["cores"] or 1
    loads = {name: p.context.get("load_avg", []) for name, p in programs.items() if p.ok}
    peak_load = max((l[0] for l in loads.values() if l), default=0.0)
    use_cpu = peak_load > cores / 2
    now = datetime.datetime.now(datetime.timezone.utc)

    out = {}
    md = [
        "# trellis performance report",
        "",
        f"Generated by `{args.command}` on {now:%Y-%m-%d %H:%M} UTC"
        + (" — **fast mode** (tiny subset, few repetitions: checks the pipeline, not the figures)"
           if args.mode == "fast" else "") + ".",
        "",
        "## Machine",
        "",
        md_table(["", ""], [
            ("CPU", info["cpu"]), ("cores", cores), ("OS", info["os"]), ("compiler", info["compiler"]),
            ("build type", info["build_type"]), ("flags", f"`{info['flags']}`"),
            ("load average (1, 5, 15 min) at the start of each program",
             "; ".join(f"{n}: {', '.join(f'{x:.2f}' for x in l)}" for n, l in loads.items() if l) or "–"),
            ("Google Benchmark", f"{sweep.context.get('library_build_type', '?')} library build, "
                                 f"{sweep.context.get('num_cpus', '?')} CPUs at {sweep.context.get('mhz_per_cpu', '?')} MHz"),
        ]),
        "",
        ("The load average exceeded half the cores (the machine is shared), so the times below are "
         "**CPU times** of the benchmark thread: they exclude the waiting for other processes but not "
         "their cache pollution; wall times would be larger and noisier. "
         if use_cpu else "The machine was quiet enough (load ≤ half the cores): times are wall-clock. ")
        + "Every time is the median over the benchmark's repetitions, ± the largest deviation of a "
        "repetition from it.",
        "",
        "## 1. Linearization: time against the number of bodies",
        "",
        "Exact = `computeLinearization` (the core's exact A, B); central / forward = finite "
        "differences of `computeDynamics` over z = [q; q̇; u] (2(2n+m) and 2n+m+1 evaluations) at "
        "h = ε^(1/3) and ε^(1/2). Models (bench/models.hpp): planar chains N = 2 … 64 without and "
        "with one constraint row on the tip, 3D chains, and the 20-joint hand tree without and with "
        "a 3D point constraint on the index fingertip; one input per joint. The core computes in "
        "`double` only (it is not templated on the scalar type), so there is no automatic-"
        "differentiation series. Source: bench/linearization_sweep.cpp.",
        "",
        section_scaling(sweep, use_cpu, args.figures, rel, out),
        "## 2. Linearization: error against time",
        "",
        section_accuracy(sweep, use_cpu, args.figures, rel, out) + run_line(sweep),
    ]
    # The headline figures go right under the description of section 1, before its plot.
    summary_lines = summarize_scaling(out, use_cpu)
    if summary_lines:
        at = next(i for i, line in enumerate(md) if line.endswith("Source: bench/linearization_sweep.cpp."))
        md[at + 1:at + 1] = ["", *summary_lines[:-1]]

    md += ["## 3. Riccati: error against time over the tolerance sweep", ""]
    ric = programs["riccati"]
    md.append(section_riccati(ric, use_cpu, args.figures, rel) + run_line(ric) if ric.ok
              else f"_Skipped: {ric.status}._ (bench/riccati_bench.cpp, target trellis_bench_riccati.)\n")
    md += ["## 4. Trajectory optimization: solve time and iterations against knots", ""]
    opt = programs["optimization"]
    md.append(section_optimization(opt, use_cpu, args.figures, rel) + run_line(opt) if opt.ok
              else f"_Skipped: {opt.status}._ (bench/optimization_bench.cpp, target trellis_bench_optimization.)\n")
    md += ["## 5. The hand's main job: time per stage", ""]
    summary = parse_hand_summary(args.hand_summary)
    md.append(section_hand(summary, args.hand_summary, args.figures, rel) if summary
              else f"_No summary found at `{display_path(args.hand_summary or 'output/hand/summary.txt')}`: run "
                   "examples/main_job/hand_main_job (it writes output/hand/summary.txt) and re-run the "
                   "report._\n")

    # "not built" / "not run" are notes (an optional program may be absent); "failed" is a failure.
    failures = [f"{name}: {p.status}" for name, p in programs.items() if p.status.startswith("failed")]
    failures += [f"{name}: {f}" for name, p in programs.items() for f in p.failures]
    md += ["## Reproducing", "",
           "```sh",
           "scripts/perf_report.sh                 # configure + build build/ (Release), run, write docs/performance.md",
           "scripts/perf_report.sh --fast          # seconds: a subset, report in a temporary folder (CI)",
           "scripts/perf_report.sh --help          # options (build directory, output folder, repetitions)",
           "```", "",
           "The raw Google Benchmark JSON and console logs are not kept by default; `--keep-json` copies "
           "them to `performance/raw/` beside the report.",
           "",
           "Times on a shared machine are noisy; the load-independent measure is instructions per call "
           "(callgrind on `trellis_bench_profile`, recipe and figures in bench/README.md, including "
           "the effect of the `TRELLIS_NATIVE` build option, -march=native, off by default).",
           ""]
    if failures:
        md += ["## Failures", ""] + [f"- {f}" for f in failures] + [""]
    kept = kept_section(args.md)
    with open(args.md, "w", encoding="utf-8") as fh:
        fh.write("\n".join(md).rstrip() + "\n")
        if kept:
            fh.write("\n" + kept.rstrip() + "\n")
    print(f"perf_report.py: wrote {args.md} and the plots in {args.figures}")
    for f in failures:
        print(f"perf_report.py: FAILED {f}", file=sys.stderr)
    return 1 if failures else 0


def summarize_scaling(out, use_cpu):
    """A few sentences with the headline figures (computed, not written by hand)."""
    cases = out.get("scaling_cases", {})
    lines = []
    exps = {(f, nc, m): p for f, nc, m, p, _, _ in out.get("exponents", [])}
    for family in ("planar", "spatial"):
        fits = [(m, exps.get((FAMILY_TITLE[family], 0, m), (None, None))) for m in METHODS]
        if all(p is not None for _, (p, _) in fits):
            lines.append(f"**Growth with N ({FAMILY_TITLE[family]}s, N ≥ {FIT_MIN_N}):** " +
                         ", ".join(f"{m} t ∝ N^({fmt_exponent(*pe)})" for m, pe in fits) + ".")
    for family, nc, n in (("planar", 0, 64), ("hand", 0, 20), ("hand", 3, 20)):
        by = cases.get((family, nc), {})
        runs = {m: by.get(m, {}).get(n) for m in METHODS}
        if all(runs.values()):
            t = {m: r.time(use_cpu)[0] for m, r in runs.items()}
            e, unc = runs["exact"].counter("err"), runs["exact"].counter("ref_unc")
            within = e is not None and unc is not None and e <= 2 * unc
            exact_err = (f"differs from the reference by {fmt_err(e)}, "
                         + (f"of the order of the reference's own uncertainty {fmt_err(unc)}" if within
                            else f"more than twice the reference's own uncertainty {fmt_err(unc)}"))
            lines.append(f"- {FAMILY_TITLE[family]}, N = {n}" + (f", {nc} constraint rows" if nc else "") +
                         f": exact {fmt_us(t['exact'])} ({exact_err}), "
                         f"central {fmt_us(t['central'])} ({t['central'] / t['exact']:.1f}× slower, error "
                         f"{fmt_err(runs['central'].counter('err'))}), forward {fmt_us(t['forward'])} "
                         f"({t['forward'] / t['exact']:.1f}×, error {fmt_err(runs['forward'].counter('err'))}).")
    return lines + [""] if lines else []


if __name__ == "__main__":
    sys.exit(main())
