#!/usr/bin/env bash
# scripts/perf_report.sh — build the benchmarks (Release), run them, write the performance report.
#
#   scripts/perf_report.sh [--fast] [--build-dir DIR] [--out DIR] [--no-build] [--keep-json]
#                          [--hand-summary FILE] [--repetitions N] [--min-time SECONDS] [--jobs N]
#
# Full mode (default, about five minutes on two cores): configures DIR (default <repo>/build) with
# CMAKE_BUILD_TYPE=Release and TRELLIS_BUILD_BENCHMARKS=ON, builds the benchmark programs
#   trellis_bench_linearization_sweep  (required)   linearization time vs N, error vs time
#   trellis_bench_riccati              (optional)   Riccati error vs time over tolerances
#   trellis_bench_optimization         (optional)   trajectory optimization vs knots
# runs each with Google Benchmark's JSON output and repetitions, and writes
# <out>/performance.md and <out>/performance/*.png (default out: <repo>/docs) with
# bench/perf_report.py. An optional program that does not build or is not configured (e.g.
# Ipopt missing) becomes a note in its section; the hand's main job section is read from
# output/hand/summary.txt when it exists.
#
# --fast: a few seconds — a small subset of each program, two repetitions, tiny minimum times;
# the report goes to a new temporary folder unless --out is given (CI runs this so the generator
# cannot rot; its figures are not meant to be read).
# --no-build: use the programs already built in DIR (for CTest, which must not rebuild its own tree).
# --keep-json: keep the raw JSON and console logs in <out>/performance/raw/.
#
# Exit status: 0 report written, every program that ran succeeded; 1 a benchmark program failed
# or reported an error (the report is still written, listing it); 2 the report could not be made
# (configure / build of the required program failed, bad arguments, matplotlib missing).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(dirname "$here")"

usage() { sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; }
die() { echo "perf_report.sh: $*" >&2; exit 2; }

fast=0 build_dir="$repo/build" out="" no_build=0 keep_json=0 jobs=2
hand_summary="$repo/output/hand/summary.txt" repetitions="" min_time=""
while (($#)); do
  case "$1" in
    --fast) fast=1 ;;
    --build-dir) build_dir="${2:?--build-dir needs a directory}"; shift ;;
    --out) out="${2:?--out needs a directory}"; shift ;;
    --no-build) no_build=1 ;;
    --keep-json) keep_json=1 ;;
    --hand-summary) hand_summary="${2:?--hand-summary needs a file}"; shift ;;
    --repetitions) repetitions="${2:?--repetitions needs a number}"; shift ;;
    --min-time) min_time="${2:?--min-time needs seconds}"; shift ;;
    --jobs|-j) jobs="${2:?--jobs needs a number}"; shift ;;
    -h|--help) usage; exit 0 ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
  shift
done
[[ -z "$repetitions" || "$repetitions" =~ ^[1-9][0-9]*$ ]] || die "--repetitions must be a positive integer, got '$repetitions'"
[[ -z "$min_time" || "$min_time" =~ ^[0-9]*\.?[0-9]+$ ]] || die "--min-time must be a number of seconds, got '$min_time'"
[[ "$jobs" =~ ^[1-9][0-9]*$ ]] || die "--jobs must be a positive integer, got '$jobs'"

if [[ -z "$out" ]]; then
  if ((fast)); then out="$(mktemp -d "${TMPDIR:-/tmp}/trellis-perf-fast.XXXXXX")"; else out="$repo/docs"; fi
fi
mkdir -p "$out/performance"
out="$(cd "$out" && pwd)"
build_dir="$(mkdir -p "$build_dir" && cd "$build_dir" && pwd)"

# Debian's interpreter has python3-matplotlib; a python3 earlier on PATH (pyenv) may not.
python=python3
[[ -x /usr/bin/python3 ]] && python=/usr/bin/python3

results="$(mktemp -d "${TMPDIR:-/tmp}/trellis-perf-results.XXXXXX")"
trap 'rm -rf "$results"' EXIT
start=$(date +%s)

# ---- Build ---------------------------------------------------------------------------------------
programs=(linearization_sweep riccati optimization)
declare -A status
if ((!no_build)); then
  echo "perf_report.sh: configuring $build_dir (Release, benchmarks on)" >&2
  cmake -S "$repo" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release -DTRELLIS_BUILD_BENCHMARKS=ON \
    >"$results/configure.log" 2>&1 || { cat "$results/configure.log" >&2; die "configuring $build_dir failed"; }
  for p in "${programs[@]}"; do
    echo "perf_report.sh: building trellis_bench_$p" >&2
    if ! cmake --build "$build_dir" --target "trellis_bench_$p" -j "$jobs" >"$results/build_$p.log" 2>&1; then
      [[ "$p" == linearization_sweep ]] && { tail -n 30 "$results/build_$p.log" >&2; die "building trellis_bench_$p failed"; }
      if grep -qiE "unknown target|no rule to make target" "$results/build_$p.log"; then
        status[$p]="not built: the target trellis_bench_$p is not configured in this build"
      else
        status[$p]="not built: trellis_bench_$p does not compile at the moment ($( (grep -m1 -E 'error' "$results/build_$p.log" || true) | cut -c1-160 | tr -d '`|'))"
      fi
      echo "perf_report.sh: ${status[$p]}" >&2
    fi
  done
fi

binary() { find "$build_dir" -name "trellis_bench_$1" \( -type f -o -type l \) -perm -u+x -print -quit 2>/dev/null; }

# ---- Run -----------------------------------------------------------------------------------------
# Per program: filter, repetitions, minimum time per repetition (seconds), time limit.
if ((fast)); then
  declare -A filter=(
    [linearization_sweep]='^Scaling/.*/planar/N:(2|8|32)/nc:0$|^Scaling/.*/hand/|^Accuracy/(central|forward)/hand/N:20/nc:0/h:(2|5|8)$'
    [riccati]='^BM_Riccati/n:2/method:(0|3|4)/tol:(4|8)$'
    [optimization]='^solve/problem:0/knots:25/fd:(0|1)'
  )
  declare -A reps=([linearization_sweep]=2 [riccati]=2 [optimization]=1)
  declare -A mintime=([linearization_sweep]=0.002 [riccati]=0.001 [optimization]=0.001)
  limit=120
else
  # Riccati: the dense-LU BDF stops at nx = 20 in the benchmark itself and costs ~10 s per solve
  # there, and nx = 80 at rtol 1e-10 ~5 s per method: both left out to keep the run near five
  # minutes (run trellis_bench_riccati directly for them).
  declare -A filter=(
    [linearization_sweep]='.'
    [riccati]='^BM_Riccati/n:(2|10)/|^BM_Riccati/n:20/method:(0|2|3|4)/|^BM_Riccati/n:40/method:(0|2|3|4)/tol:(3|4|5|6|7|8)$'
    [optimization]='^(solve|refine)/'  # the swingup and swingupStart families (minutes) run by hand: bench/optimization_bench.cpp
  )
  declare -A reps=([linearization_sweep]=5 [riccati]=2 [optimization]=3)
  declare -A mintime=([linearization_sweep]=0.03 [riccati]=0.01 [optimization]=0.001)
  limit=900
fi
failed=0
for p in "${programs[@]}"; do
  [[ -n "${status[$p]:-}" ]] && { echo "${status[$p]}" >"$results/$p.status"; continue; }
  bin="$(binary "$p")"
  if [[ -z "$bin" ]]; then
    [[ "$p" == linearization_sweep ]] && die "trellis_bench_$p not found in $build_dir (build it, or drop --no-build)"
    echo "not built: trellis_bench_$p not found in the build directory" >"$results/$p.status"
    echo "perf_report.sh: trellis_bench_$p not found in $build_dir; its section will say so" >&2
    continue
  fi
  r="${repetitions:-${reps[$p]}}"
  t="${min_time:-${mintime[$p]}}"
  echo "perf_report.sh: running trellis_bench_$p (repetitions $r, min time $t s)" >&2
  args=(--benchmark_filter="${filter[$p]}" --benchmark_repetitions="$r" --benchmark_min_time="$t")
  echo "trellis_bench_$p ${args[*]}" >"$results/$p.args"
  rc=0
  timeout "$limit" "$bin" "${args[@]}" --benchmark_out="$results/$p.json" --benchmark_out_format=json \
    --benchmark_format=console >"$results/$p.log" 2>&1 || rc=$?
  if ((rc == 0)) && [[ -s "$results/$p.json" ]]; then
    echo ok >"$results/$p.status"
  else
    ((rc == 124)) && why="timed out after $limit s" || why="exit status $rc"
    echo "failed: trellis_bench_$p $why" >"$results/$p.status"
    echo "perf_report.sh: trellis_bench_$p failed ($why); last lines of its output:" >&2
    tail -n 15 "$results/$p.log" >&2
    failed=1
  fi
done

# ---- Report --------------------------------------------------------------------------------------
cmdline="scripts/perf_report.sh"
((fast)) && cmdline+=" --fast"
rc=0
"$python" "$repo/bench/perf_report.py" --results "$results" --md "$out/performance.md" \
  --figures "$out/performance" --build-dir "$build_dir" --hand-summary "$hand_summary" \
  --mode "$( ((fast)) && echo fast || echo full)" --command "$cmdline" || rc=$?
if ((keep_json)); then
  mkdir -p "$out/performance/raw"
  cp "$results"/*.json "$results"/*.log "$results"/*.status "$out/performance/raw/" 2>/dev/null || true
fi
echo "perf_report.sh: $((($(date +%s) - start))) s; report: $out/performance.md" >&2
((rc >= 2)) && exit 2
((rc != 0 || failed)) && exit 1
exit 0
