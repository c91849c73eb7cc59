#!/usr/bin/env python3
"""Tests of bench/perf_report.py on manufactured Google Benchmark JSON (no benchmark is run).

The manufactured times follow t = c·N^p exactly, so the growth exponents the report states must
be the p put in (to the two printed decimals); the hand summary's stages must come back as
written; and the exit status must tell a failed or missing program from a good run.

    /usr/bin/python3 tests/perf/test_perf_report.py      (needs python3-matplotlib)
"""
import json
import os
import re
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "bench"))
import perf_report  # noqa: E402

# (method, c [µs], p): distinct exponents so that a mixed-up series would show.
MANUFACTURED = {"exact": (0.7, 2.25), "central": (3.0, 2.75), "forward": (1.9, 3.1)}


def run_entries(name, times_us, counters, label=""):
    """One Google Benchmark JSON entry per repetition, plus the median aggregate GB would add."""
    out = []
    for i, t in enumerate(times_us):
        e = {"name": name, "run_name": name, "run_type": "iteration", "repetitions": len(times_us),
             "repetition_index": i, "threads": 1, "iterations": 10, "real_time": t * 1.1,
             "cpu_time": t, "time_unit": "us"}
        e.update(counters)
        if label:
            e["label"] = label
        out.append(e)
    out.append({"name": name + "_median", "run_name": name, "run_type": "aggregate",
                "aggregate_name": "median", "real_time": 0.0, "cpu_time": 0.0, "time_unit": "us"})
    return out


def write_program(d, name, benchmarks, load=0.1, status="ok"):
    with open(os.path.join(d, name + ".status"), "w", encoding="utf-8") as fh:
        fh.write(status + "\n")
    with open(os.path.join(d, name + ".json"), "w", encoding="utf-8") as fh:
        json.dump({"context": {"load_avg": [load, load, load], "num_cpus": 2}, "benchmarks": benchmarks}, fh)


def sweep_benchmarks():
    b = []
    for family, ncs, ns in (("planar", (0, 1), (2, 4, 8, 16, 32, 64)), ("spatial", (0,), (2, 8, 64)),
                            ("hand", (0, 3), (20,))):
        for nc in ncs:
            for n in ns:
                for method, (c, p) in MANUFACTURED.items():
                    t = c * n ** p
                    # Repetitions spread symmetrically about t: the median is t itself.
                    b += run_entries(f"Scaling/{method}/{family}/N:{n}/nc:{nc}", [0.9 * t, t, 1.1 * t],
                                     {"err": 3e-14 if method == "exact" else 2e-8, "ref_unc": 1e-13})
    for k in range(2, 11):
        for method in ("central", "forward"):
            b += run_entries(f"Accuracy/{method}/hand/N:20/nc:0/h:{k}", [100.0, 101.0, 102.0],
                             {"err": 10.0 ** -k + 1e-16 * 10.0 ** k})
    return b


SUMMARY = """
hand main job — summary
  stage                                                         time [s]
  load the hand scene                                              0.012
  trajectory optimization (Ipopt)                                 12.500
  TV-LQR gains                                                     0.250
  whole job                                                       12.900

  linearization: exact 10.0 µs per knot, central differences 90.0 µs (relative difference 1.0e-08)
"""


class PerfReportTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = self.tmp.name
        self.results = os.path.join(self.dir, "results")
        os.makedirs(self.results)
        self.md = os.path.join(self.dir, "docs", "performance.md")
        self.fig = os.path.join(self.dir, "docs", "performance")

    def tearDown(self):
        self.tmp.cleanup()

    def generate(self, hand_summary=None):
        args = ["--results", self.results, "--md", self.md, "--figures", self.fig, "--mode", "fast"]
        if hand_summary:
            args += ["--hand-summary", hand_summary]
        return perf_report.main(args)

    def read_md(self):
        with open(self.md, encoding="utf-8") as fh:
            return fh.read()

    def test_exponents_tables_and_plots(self):
        write_program(self.results, "linearization_sweep", sweep_benchmarks())
        write_program(self.results, "riccati", [], status="not built: target missing")
        summary = os.path.join(self.dir, "summary.txt")
        with open(summary, "w", encoding="utf-8") as fh:
            fh.write(SUMMARY)
        self.assertEqual(self.generate(summary), 0)
        md = self.read_md()
        for method, (_, p) in MANUFACTURED.items():
            # Table row: | planar chain | 0 | <method> | p (N ≥ 8) | p (all N) | ...
            # The manufactured points lie exactly on the line: the slope's standard error is 0.
            row = re.search(rf"\| planar chain \| 0 \| {method} \| ([0-9.]+) ± ([0-9.]+) \| ([0-9.]+) \|", md)
            self.assertIsNotNone(row, method)
            self.assertEqual(row.group(1), f"{p:.2f}")
            self.assertEqual(row.group(2), "0.00")
            self.assertEqual(row.group(3), f"{p:.2f}")
        # Median of the wall times (real_time = 1.1·cpu_time in the manufactured runs), not GB's
        # aggregate (manufactured as 0): exact at N = 64.
        self.assertIn(perf_report.fmt_us(1.1 * 0.7 * 64 ** 2.25) + " ±10%", md)
        # Load 0.1 on the manufactured machine's cores: wall-clock times are reported.
        self.assertIn("times are wall-clock", md)
        self.assertIn("| TV-LQR gains | 0.250 |", md)
        self.assertIn("**12.900**", md)
        self.assertIn("_Skipped: not built: target missing._", md)
        for png in ("linearization_scaling.png", "linearization_error_vs_time.png", "hand_main_job_stages.png"):
            self.assertTrue(os.path.getsize(os.path.join(self.fig, png)) > 1000, png)
            self.assertIn(f"](performance/{png})", md)

    def test_riccati_and_optimization_sections(self):
        write_program(self.results, "linearization_sweep", sweep_benchmarks())
        ric = []
        for n, method, label in ((2, 0, "BDF"), (2, 3, "Adams"), (10, 0, "BDF")):
            for e in (3, 6, 10):
                failed = n == 10 and e == 10  # a solve that did not succeed: listed, not plotted
                ric += run_entries(f"BM_Riccati/n:{n}/method:{method}/tol:{e}", [1000.0 * e] * 2,
                                   {"nx": 2 * n, "rtol": 10.0 ** -e, "max_rel_err": -1.0 if failed else 10.0 ** -e,
                                    "ok": 0 if failed else 1, "steps": 10 * e}, label)
        write_program(self.results, "riccati", ric)
        # Google Benchmark writes the user counter "iterations" (Ipopt's) after its own field of
        # the same name: the JSON object has the key twice, which json.dump cannot produce.
        entries = []
        for knots, fd, ipopt in ((25, 0, 26), (50, 0, 23), (25, 1, 27), (50, 1, 24)):
            name = f"solve/problem:0/knots:{knots}/fd:{fd}/iterations:3/real_time"
            entries.append(
                f'{{"name": "{name}", "run_name": "{name}", "run_type": "iteration", "repetitions": 1, '
                f'"repetition_index": 0, "threads": 1, "iterations": 3, "real_time": {knots * (2 + fd)}, '
                f'"cpu_time": {knots}, "time_unit": "ms", "cost": 5.34, "cpu_ms": {knots}, '
                f'"iterations": {ipopt}, "success": 1, "viol": 1e-15, '
                f'"label": "cart_pole_swingup {"finite-difference" if fd else "exact"}"}}')
        with open(os.path.join(self.results, "optimization.json"), "w", encoding="utf-8") as fh:
            fh.write('{"context": {"load_avg": [0.1, 0.1, 0.1]}, "benchmarks": [' + ", ".join(entries) + "]}")
        with open(os.path.join(self.results, "optimization.status"), "w", encoding="utf-8") as fh:
            fh.write("ok\n")
        self.assertEqual(self.generate(), 0)
        md = self.read_md()
        self.assertIn("| 4 | Adams | 1e-06 |", md)
        # Error ≤ 1e-6 first reached at rtol 1e-6 (CPU 6000 µs, wall 1.1× that) by both methods
        # at nx = 4; at nx = 20 only by BDF (Adams was not run there).
        self.assertIn("- nx = 4: Adams 6.6 ms, BDF 6.6 ms\n- nx = 20: BDF 6.6 ms\n", md)
        self.assertIn("nx = 20, BDF, rtol 1e-10", md)
        self.assertNotIn("| 20 | BDF | 1e-10 |", md)
        # Ipopt's iteration count, not Google Benchmark's 3; wall time (load 0.1) per solve.
        self.assertIn("| cart_pole_swingup | 50 | FD | 150 ms | 24 | yes |", md)
        for png in ("riccati_error_vs_time.png", "optimization_vs_knots.png"):
            self.assertTrue(os.path.getsize(os.path.join(self.fig, png)) > 1000, png)

    def test_cpu_time_when_loaded(self):
        write_program(self.results, "linearization_sweep", sweep_benchmarks(), load=50.0)
        self.assertEqual(self.generate(), 0)
        md = self.read_md()
        self.assertIn("**CPU times**", md)
        self.assertIn(perf_report.fmt_us(0.7 * 64 ** 2.25) + " ±10%", md)

    def test_benchmark_error_fails_but_writes_the_report(self):
        b = sweep_benchmarks() + [{"name": "Scaling/exact/planar/N:128/nc:0", "run_name": "Scaling/exact/planar/N:128/nc:0",
                                   "error_occurred": True, "error_message": "computeLinearization failed: singular"}]
        write_program(self.results, "linearization_sweep", b)
        self.assertEqual(self.generate(), 1)
        self.assertIn("computeLinearization failed: singular", self.read_md())

    def test_failed_optional_program_fails(self):
        write_program(self.results, "linearization_sweep", sweep_benchmarks())
        write_program(self.results, "optimization", [], status="failed: trellis_bench_optimization exit status 134")
        self.assertEqual(self.generate(), 1)
        self.assertIn("exit status 134", self.read_md())

    def test_hand_written_tail_is_kept(self):
        """The generated part is replaced, the part after the marker survives regeneration."""
        write_program(self.results, "linearization_sweep", sweep_benchmarks())
        os.makedirs(os.path.dirname(self.md))
        tail = perf_report.KEPT_MARKER + "\n\n## History\n\n| model | before | after |\n|---|---|---|\n"
        with open(self.md, "w", encoding="utf-8") as fh:
            fh.write("# an old generated report\n\nstale figures\n\n" + tail)
        self.assertEqual(self.generate(), 0)
        md = self.read_md()
        self.assertNotIn("stale figures", md)
        self.assertTrue(md.startswith("# trellis performance report"))
        self.assertTrue(md.endswith(tail), md[-300:])
        self.assertEqual(md.count(perf_report.KEPT_MARKER), 1)
        self.assertEqual(self.generate(), 0)  # again: the tail is kept once, not duplicated
        again = self.read_md()
        self.assertTrue(again.endswith(tail))
        self.assertEqual(again.count(perf_report.KEPT_MARKER), 1)

    def test_missing_sweep_cannot_make_a_report(self):
        write_program(self.results, "linearization_sweep", [], status="failed: exit status 1")
        self.assertEqual(self.generate(), 2)
        self.assertFalse(os.path.exists(self.md))

    def test_hand_summary_without_table_is_an_error(self):
        write_program(self.results, "linearization_sweep", sweep_benchmarks())
        bad = os.path.join(self.dir, "summary.txt")
        with open(bad, "w", encoding="utf-8") as fh:
            fh.write("nothing here\n")
        self.assertEqual(self.generate(bad), 2)


if __name__ == "__main__":
    unittest.main()
