#!/bin/sh
# bench/second_order_callgrind.sh — callgrind instruction counts per call of the second-order
# contraction, the full tensors and the central differences of the exact Jacobians, each against
# one exact linearization (issue 30's cost figures). Per-call counts are the difference of the
# totals of two runs (ITER1 and ITER2 calls) over ITER2 − ITER1, which removes the set-up.
#
#   bench/second_order_callgrind.sh BUILD_DIR [what...]     (default: lin contract tensors fdjac;
#   also contract_tape: the contraction on the recorded tape where the tree pass would run)
set -eu
build=${1:?usage: $0 BUILD_DIR [lin contract contract_tape tensors fdjac]}
shift
whats=${*:-"lin contract tensors fdjac"}
prog="$build/bench/trellis_bench_second_order_profile"
scene="$(dirname "$0")/../examples/scenes/hand.json"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
count() {  # count ARGS... → total instructions (Ir) of one run
  valgrind --tool=callgrind --callgrind-out-file="$tmp/out" "$prog" "$@" > /dev/null 2>&1
  sed -n 's/^summary: *//p' "$tmp/out"
}
printf '%-22s %-8s %14s %10s\n' model what Ir/call "x lin"
for model in "planar 10 0" "spatial 40 0" "hand 20 0" "hand 20 1" "scene $scene 0"; do
  lin=""
  for what in $whats; do
    set -- $model
    i1=1; i2=3
    [ "$what" = fdjac ] && { i1=1; i2=2; }
    a=$(count "$1" "$2" "$3" "$what" "$i1")
    b=$(count "$1" "$2" "$3" "$what" "$i2")
    per=$(( (b - a) / (i2 - i1) ))
    [ "$what" = lin ] && lin=$per
    ratio=$( [ -n "$lin" ] && awk -v p="$per" -v l="$lin" 'BEGIN { printf "%.2f", p / l }' || echo "-")
    label="$1/$2/nc$3"
    [ "$1" = scene ] && label="hand_scene"
    printf '%-22s %-8s %14d %10s\n' "$label" "$what" "$per" "$ratio"
  done
done
