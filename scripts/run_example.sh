#!/usr/bin/env bash
# scripts/run_example.sh NAME [OUTPUT_DIR] — one trajectory-optimization example end to end with the
# `trellis` command-line tool:
#   1. trellis optimize  examples/problems/NAME.json            → reference.csv (Ipopt, exact Jacobians,
#      checked a posteriori against the exact dynamics and refined until consistent)
#   2. trellis gains     SCENE --trajectory reference.csv       → gains.csv     (TV-LQR, CVODES)
#   3. trellis simulate  SCENE ... --perturb-random σ --seed k  → closed_loop_k.csv (nonlinear plant)
#      (and once without feedback: the same perturbation with zero gains, to show what feedback buys)
#   4. scripts/plot_run.py → states.png, inputs.png, gains.png, tracking_error.png
#   5. trellis view      SCENE --trajectory reference.csv --trajectory closed_loop_k.csv → view.html (3D)
# NAME: cart_pole_swingup, acrobot_swingup, paper_pendulum_transfer or skate_lane_change (any examples/problems/*.json
# works with the default weights). Edit the problem file and run again to explore.
# Needs a built tree (cmake --build --preset default); TRELLIS=path overrides the program.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
name="${1:?usage: scripts/run_example.sh NAME [OUTPUT_DIR]  (NAME: a file examples/problems/NAME.json)}"
out="${2:-output/$name}"
problem="$root/examples/problems/$name.json"
trellis="${TRELLIS:-$root/build/cli/trellis}"
[[ -f "$problem" ]] || { echo "run_example.sh: no problem file $problem" >&2; exit 2; }
[[ -x "$trellis" ]] || { echo "run_example.sh: $trellis not built (cmake --build --preset default)" >&2; exit 2; }
python=python3
[[ -x /usr/bin/python3 ]] && python=/usr/bin/python3   # Debian's, which has python3-matplotlib
mkdir -p "$out"

# The scene named in the problem file, relative to the problem file.
scene="$("$python" -c 'import json,os,sys; p=sys.argv[1]; print(os.path.normpath(os.path.join(os.path.dirname(p), json.load(open(p))["scene"])))' "$problem")"

# Feedback weights and perturbation size per example (full state [q; q'], inputs).
case "$name" in
  cart_pole_swingup)       Q=10,10,1,1;  R=0.1; Qf=100; sigma=0.05 ;;
  acrobot_swingup)         Q=10,10,1,1;  R=0.1; Qf=100; sigma=0.02 ;;
  paper_pendulum_transfer) Q=10,10,1,1;  R=0.1; Qf=100; sigma=0.05 ;;
  skate_lane_change)       Q=10;         R=1;   Qf=100; sigma=0.05 ;;
  *)                       Q=10;         R=1;   Qf=100; sigma=0.02 ;;
esac

step() { printf '\n== %s\n' "$*"; }
SECONDS=0
step "1/4 optimize: $problem"
"$trellis" optimize "$problem" --out "$out/reference.csv" | tee "$out/optimize.txt"
step "2/4 gains: TV-LQR along the optimized trajectory (Q=$Q R=$R Qf=$Qf)"
"$trellis" gains "$scene" --trajectory "$out/reference.csv" --Q "$Q" --R "$R" --Qf "$Qf" \
  --dt 0.01 --out "$out/gains.csv" | tee "$out/gains.txt"
step "3/4 simulate: closed loop from 3 perturbed starts (σ = $sigma, seeds 1..3), and one open loop"
closed=()
for seed in 1 2 3; do
  "$trellis" simulate "$scene" --trajectory "$out/reference.csv" --gains "$out/gains.csv" \
    --perturb-random "$sigma" --seed "$seed" --output-step 0.01 --out "$out/closed_loop_$seed.csv" | tee "$out/simulate_$seed.txt"
  closed+=(--closed "$out/closed_loop_$seed.csv")
done
# Open loop for comparison: the same perturbation (seed 1) under zero gains.
"$python" - "$out/gains.csv" "$out/zero_gains.csv" <<'EOF'
import csv, sys
lines = open(sys.argv[1]).read().splitlines()
# The metadata comment lines and the named header are kept: the zero gains stay checked against
# the scene and the rate like the real ones.
head = 0
while lines[head].startswith("#"):
    head += 1
rows = list(csv.reader(lines[head + 1:]))
with open(sys.argv[2], "w", newline="") as f:
    f.write("\n".join(lines[:head + 1]) + "\n")
    w = csv.writer(f, lineterminator="\n")
    for r in rows:
        w.writerow([r[0]] + ["0"] * (len(r) - 1))
EOF
if "$trellis" simulate "$scene" --trajectory "$out/reference.csv" --gains "$out/zero_gains.csv" \
     --perturb-random "$sigma" --seed 1 --output-step 0.01 --out "$out/open_loop.csv" > "$out/open_loop.txt" 2>&1; then
  echo "open loop (no feedback), same perturbation:"; cat "$out/open_loop.txt"
  closed+=(--closed "$out/open_loop.csv")
else
  echo "open loop (no feedback): $(tail -n 1 "$out/open_loop.txt")"
fi
step "4/4 plots"
"$python" "$root/scripts/plot_run.py" --title "$name" --reference "$out/reference.csv" \
  --scene "$scene" --trellis "$trellis" --gains "$out/gains.csv" "${closed[@]}" --out "$out"
step "view: the reference and the closed loops in 3D ($out/view.html, docs/viewer.md)"
views=(--trajectory "$out/reference.csv")
for seed in 1 2 3; do views+=(--trajectory "$out/closed_loop_$seed.csv"); done
"$trellis" view "$scene" "${views[@]}" --title "$name: reference and closed loops" --out "$out/view.html"
printf '\n%s: done in %d s; files in %s/\n' "$name" "$SECONDS" "$out"
