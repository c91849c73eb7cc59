#!/usr/bin/env bash
# bench/funnel_scaling.sh — issue 29's figures for `trellis funnel`: closed loops per second per
# core on the cart-pole swing-up and on the hand's holding motion (hand_hold_job) (one closed loop each, in the
# funnel's configuration), and the scaling with threads and with MPI ranks (trellis-mpi), each
# run checked byte for byte against the one-thread table. Prints a markdown table; every figure
# is the median of REPETITIONS runs with the spread (min..max) beside it.
#
#   bench/funnel_scaling.sh [BUILD_DIR]        (default build/; needs cli/trellis, cli/trellis-mpi,
#                                                examples/hand/hand_hold_job built)
# Environment: REPETITIONS (3), CART_SAMPLES (per level, 40), HAND_SAMPLES (per level, 3),
# MAX_RANKS (8: 1, 2, 4, 8 ranks, oversubscribed beyond the cores to check the split).
# mpirun --bind-to none: Open MPI binds each rank to a core by default (np <= 2), which on a shared
# machine pins it to a busy core and serializes a rank's threads.
# Wall time is only meaningful on a quiet machine: the table repeats the load average; the CPU
# time (user + system of the command and its children) gives the per-sample cost under load.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
trellis="$build/cli/trellis"
mpi="$build/cli/trellis-mpi"
hand_job="$build/examples/hand/hand_hold_job"
reps="${REPETITIONS:-3}"
cart_n="${CART_SAMPLES:-40}"
hand_n="${HAND_SAMPLES:-3}"
max_ranks="${MAX_RANKS:-8}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none

# run NAME CMD...: REPETITIONS runs; appends "NAME wall cpu" lines to $work/times.
run() {
  local name=$1; shift
  for ((r = 0; r < reps; ++r)); do
    local TIMEFORMAT='%R %U %S'
    { time "$@" > "$work/last.txt" 2>&1; } 2> "$work/t.txt" || { cat "$work/last.txt" >&2; exit 1; }
    read -r wall user sys < "$work/t.txt"
    echo "$name $wall $(echo "$user + $sys" | bc -l)" >> "$work/times"
  done
}

cd "$work"
cart="$root/examples/scenes/cart_pole.json"
"$trellis" optimize "$root/examples/problems/cart_pole_swingup.json" --out cart_ref.csv > /dev/null 2>&1
"$trellis" gains "$cart" --trajectory cart_ref.csv --Q 10,10,1,1 --R 0.1 --Qf 100 --dt 0.01 \
  --out cart_gains.csv --cost-to-go cart_S.csv > /dev/null
# Levels around the measured funnel (rho(0) about 5 at goal 1): successes and failures both.
cart_args=(funnel "$cart" --trajectory cart_ref.csv --gains cart_gains.csv --cost-to-go cart_S.csv
           --levels 0.5,2,5,10 --goal 1 --samples "$cart_n" --seed 1 --umin -20 --umax 20)
cart_total=$((4 * cart_n))

"$hand_job" --runs 1 --no-plots --out hand > /dev/null
hand="$root/examples/scenes/hand.json"
q=$(printf '100,%.0s' $(seq 20))$(printf '1,%.0s' $(seq 19))1
"$trellis" gains "$hand" --trajectory hand/reference.csv --Q "$q" --R 1 --rtol 1e-6 --atol 5e-10 \
  --out hand_gains.csv --cost-to-go hand_S.csv > /dev/null
# The hand's closed-loop options (hand_feedback.hpp); levels inside its measured funnel.
hand_args=(funnel "$hand" --trajectory hand/reference.csv --gains hand_gains.csv --cost-to-go hand_S.csv
           --levels 1,30,300 --goal 0.01 --samples "$hand_n" --seed 1 --umin 0 --method bdf --rtol 1e-7
           --atol 5e-10 --drift-tolerance 3e-11)
hand_total=$((3 * hand_n))

run cart_threads1 "$trellis" "${cart_args[@]}" --threads 1 --out cart_t1.csv
run cart_threads2 "$trellis" "${cart_args[@]}" --threads 2 --out cart_t2.csv
cmp cart_t1.csv cart_t2.csv
run hand_threads1 "$trellis" "${hand_args[@]}" --threads 1 --out hand_t1.csv
run hand_threads2 "$trellis" "${hand_args[@]}" --threads 2 --out hand_t2.csv
cmp hand_t1.csv hand_t2.csv
for ((k = 1; k <= max_ranks; k *= 2)); do
  run "cart_ranks$k" mpirun --oversubscribe --bind-to none -n "$k" "$mpi" "${cart_args[@]}" --threads 1 --out "cart_r$k.csv"
  cmp cart_t1.csv "cart_r$k.csv"
done

echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), $(nproc) cores"
echo
echo "| run | closed loops | wall s (median, min..max) | CPU s (median) | loops/s per core (CPU) |"
echo "|---|---|---|---|---|"
for name in $(cut -d' ' -f1 times | uniq); do
  total=$cart_total
  [[ $name == hand_* ]] && total=$hand_total
  grep "^$name " times | python3 -c "
import sys, statistics
rows = [list(map(float, l.split()[1:])) for l in sys.stdin]
wall = [r[0] for r in rows]; cpu = [r[1] for r in rows]
n = $total
print(f'| $name | {n} | {statistics.median(wall):.2f} ({min(wall):.2f}..{max(wall):.2f}) | {statistics.median(cpu):.2f} | {n / statistics.median(cpu):.1f} |')"
done
