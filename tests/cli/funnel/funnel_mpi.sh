# tests/cli/funnel/funnel_mpi.sh — `trellis funnel` and `mpirun trellis-mpi funnel` (issue 29): the
# same files, byte for byte, for 1 and 2 threads and 1, 2 and 3 MPI ranks; bad input (gains, S or
# trajectory of another scene, a level that is not finite, zero samples, more ranks than samples,
# a rank that fails) is a clear error with nothing written. Run by tests_funnel.cmake in an empty
# work directory with $TRELLIS, $SOURCE_DIR and, for the part "mpi", $TRELLIS_MPI:
#   sh -eu funnel_mpi.sh threads     trellis funnel: threads, the reproduce command, bad input
#   sh -eu funnel_mpi.sh mpi         the same table from trellis-mpi on 1, 2, 3 ranks; MPI errors
# (the part "mpi" is registered only when trellis-mpi is built; without a working mpirun it fails).
# The cart-pole held upright for 3 s: a closed loop takes about 1 ms.
part=${1:?usage: funnel_mpi.sh threads|mpi}
. "$SOURCE_DIR/tests/cli/shell/common.sh"  # fail, run, err_has, out_has
absent() { for f in "$@"; do [ ! -e "$f" ] || fail "$f was written"; done; }

CART="$SOURCE_DIR/examples/scenes/cart_pole.json"
UPRIGHT="$SOURCE_DIR/examples/trajectories/cart_pole_upright.csv"
PENDULUM="$SOURCE_DIR/examples/scenes/paper_pendulum.json"
SWING="$SOURCE_DIR/examples/trajectories/paper_pendulum_swing.csv"

run 0 "$TRELLIS" gains "$CART" --trajectory "$UPRIGHT" --Q 10,10,1,1 --R 0.1 --out gains.csv --cost-to-go S.csv
run 0 "$TRELLIS" gains "$PENDULUM" --trajectory "$SWING" --out pgains.csv --cost-to-go pS.csv
# 3 start knots x 3 levels x 4 samples = 36 closed loops; failures at the upper levels.
ARGS="funnel $CART --trajectory $UPRIGHT --gains gains.csv --cost-to-go S.csv --levels 1,10,100
      --samples 4 --seed 5 --start-knots 0,5,10 --umin -10 --umax 10"

run 0 "$TRELLIS" $ARGS --threads 1 --out t1.csv --samples-out t1_samples.csv --plot t1.svg
if [ "$part" = threads ]; then
grep -q "^0,100,4,[0-3],[1-4],0$" t1.csv || fail "expected failures at level 100: $(cat t1.csv)"
grep -q "^# worst failing start t=0 " t1.csv || fail "no worst failing start: $(cat t1.csv)"
grep -q "<svg" t1.svg || fail "no plot"
# Axes with units: the cart (prismatic) in m, the pole (revolute) in rad, time in s.
grep -q ">x \[m\]<" t1.svg || fail "no unit on the cart's axis: $(grep '<text' t1.svg | head -5)"
grep -q ">theta \[rad\]<" t1.svg || fail "no unit on the pole's axis"
grep -q ">t = 3 s<" t1.svg || fail "no unit on the time axis"
[ "$(wc -l < t1_samples.csv)" = 37 ] || fail "t1_samples.csv: $(wc -l < t1_samples.csv) lines, expected 37"
# The printed command reproduces the worst start with `trellis simulate`.
reproduce=$(grep "^worst failing start at t0" out.txt | sed 's/^[^:]*: trellis //; s|CLOSED.csv|closed.csv|')
[ -n "$reproduce" ] || fail "no reproduce command: $(cat out.txt)"
run 0 "$TRELLIS" $reproduce
grep -q "tracking error" out.txt || fail "simulate did not run: $(cat out.txt)"
run 0 "$TRELLIS" $ARGS --threads 2 --out t2.csv --samples-out t2_samples.csv --plot t2.svg
cmp t1.csv t2.csv || fail "1 and 2 threads differ"
cmp t1_samples.csv t2_samples.csv || fail "1 and 2 threads: samples differ"
cmp t1.svg t2.svg || fail "1 and 2 threads: plots differ"

# Bad input: a clear error, nothing written.
run 1 "$TRELLIS" funnel "$CART" --trajectory "$UPRIGHT" --gains pgains.csv --cost-to-go S.csv --levels 1 --out bad.csv
err_has "pgains.csv"
run 1 "$TRELLIS" funnel "$CART" --trajectory "$UPRIGHT" --gains gains.csv --cost-to-go pS.csv --levels 1 --out bad.csv
err_has "pS.csv"
run 1 "$TRELLIS" funnel "$CART" --trajectory "$SWING" --gains gains.csv --cost-to-go S.csv --levels 1 --out bad.csv
err_has "paper_pendulum_swing.csv does not match the scene"
run 2 "$TRELLIS" funnel "$CART" --trajectory "$UPRIGHT" --gains gains.csv --cost-to-go S.csv --levels 1,inf --out bad.csv
err_has "--levels"
run 2 "$TRELLIS" funnel "$CART" --trajectory "$UPRIGHT" --gains gains.csv --cost-to-go S.csv --levels 1,nan --out bad.csv
err_has "--levels"
run 2 "$TRELLIS" funnel "$CART" --trajectory "$UPRIGHT" --gains gains.csv --cost-to-go S.csv --levels 1 --samples 0 --out bad.csv
err_has "--samples"
absent bad.csv
echo "ok"
exit 0
fi

[ -x "$TRELLIS_MPI" ] || fail "no trellis-mpi at '$TRELLIS_MPI'"
command -v mpirun > /dev/null || fail "trellis-mpi is built but there is no mpirun (Debian: openmpi-bin)"
# As root Open MPI needs these; in containers the shared-memory transport's single-copy mode
# (CMA) is often not permitted: use plain copies, and fall back to TCP over loopback.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none
export OMPI_MCA_rmaps_base_oversubscribe=1
MPIRUN_EXTRA=""
mpirun --oversubscribe -n 2 true > /dev/null 2>&1 || fail "mpirun -n 2 true does not run"
mpi() { ranks=$1; shift; mpirun --oversubscribe $MPIRUN_EXTRA -n "$ranks" "$TRELLIS_MPI" "$@"; }
if ! mpi 2 $ARGS --threads 1 --out probe.csv > /dev/null 2>&1; then
  MPIRUN_EXTRA="--mca btl self,tcp"
fi
rm -f probe.csv
for ranks in 1 2 3; do
  run 0 mpi "$ranks" $ARGS --threads 1 --out r$ranks.csv --samples-out r${ranks}_samples.csv --plot r$ranks.svg
  cmp t1.csv r$ranks.csv || fail "$ranks ranks differ from the plain run"
  cmp t1_samples.csv r${ranks}_samples.csv || fail "$ranks ranks: samples differ"
  cmp t1.svg r$ranks.svg || fail "$ranks ranks: plots differ"
done
run 0 mpi 2 $ARGS --threads 2 --out r2t2.csv
cmp t1.csv r2t2.csv || fail "2 ranks x 2 threads differ"

# More ranks than samples; a rank that fails; a set-up failure: an error, nothing written.
run 2 mpi 3 funnel "$CART" --trajectory "$UPRIGHT" --gains gains.csv --cost-to-go S.csv --levels 1 --samples 2 --out bad.csv
err_has "3 MPI ranks for 2 samples"
status=0
TRELLIS_MPI_FAIL_RANK=1 mpi 3 $ARGS --threads 1 --out bad.csv > out.txt 2> err.txt || status=$?
[ "$status" != 0 ] || fail "a failing rank did not fail the run"
err_has "rank 1: samples 1, 4, ...: injected failure"
run 1 mpi 2 funnel "$CART" --trajectory "$UPRIGHT" --gains pgains.csv --cost-to-go S.csv --levels 1 --out bad.csv
err_has "pgains.csv"
absent bad.csv
echo "ok"
