#!/usr/bin/env bash
# bench/run.sh — build the core benchmark (Release) if needed, run it, print a markdown table.
#
#   bench/run.sh [extra Google Benchmark flags, e.g. --benchmark_filter=hand]
#
# Environment:
#   BUILD_DIR     build directory (default: <repo>/build-bench; <BUILD_DIR>-standalone when the
#                 top-level project does not configure and bench/ is built on its own)
#   MIN_TIME      seconds per benchmark and repetition (default 0.05)
#   REPETITIONS   repetitions of each benchmark; the table reports the minimum (default 3)
#   STAT          min | median | mean over repetitions (default min)
#   OUT           JSON output (default: bench/results/core.json)
# With the defaults the whole sweep (78 benchmarks) takes one to two minutes on two cores.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(dirname "$here")"
build="${BUILD_DIR:-$repo/build-bench}"
min_time="${MIN_TIME:-0.05}"
repetitions="${REPETITIONS:-3}"
stat="${STAT:-min}"
out="${OUT:-$here/results/core.json}"
generator=()
command -v ninja >/dev/null 2>&1 && generator=(-G Ninja)

configure_top() {
  cmake -S "$repo" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
    -DTRELLIS_BUILD_BENCHMARKS=ON -DTRELLIS_BUILD_TESTS=OFF -DTRELLIS_BUILD_EXAMPLES=OFF
}
configure_standalone() {
  cmake -S "$here" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release
}

# A directory counts as configured once CMake has generated its build files.
generated() { [[ -f "$1/build.ninja" || -f "$1/Makefile" ]]; }
if ! generated "$build"; then
  # The whole project normally; bench/ alone (core + benchmarks) in <build>-standalone if the top
  # level does not configure, e.g. while another part of the tree is being rewritten.
  mkdir -p "$build"
  if ! configure_top >"$build/run-sh-configure.log" 2>&1; then
    echo "run.sh: the top-level project does not configure (see $build/run-sh-configure.log);" \
      "building bench/ alone in $build-standalone" >&2
    build="$build-standalone"
    generated "$build" || configure_standalone >&2
  fi
fi
cmake --build "$build" --target trellis_bench_core -j "$(nproc)" >&2

bin="$(find "$build" -name trellis_bench_core -type f -perm -u+x | head -n 1)"
mkdir -p "$(dirname "$out")"
"$bin" --benchmark_min_time="$min_time" --benchmark_repetitions="$repetitions" \
  --benchmark_format=console --benchmark_out_format=json --benchmark_out="$out" \
  --benchmark_counters_tabular=true "$@" >&2
python3 "$here/bench_table.py" --stat "$stat" "$out"
