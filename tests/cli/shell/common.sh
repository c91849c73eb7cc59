# Shared by the scripts of tests/cli/shell/ (sourced): $TRELLIS, $SOURCE_DIR, the work directory
# as the current one.
fail() { echo "FAILED: $*" >&2; exit 1; }
# run EXPECTED_STATUS CMD...: runs CMD with stdout in out.txt, stderr in err.txt; checks the status.
run() {
  expected=$1; shift
  status=0
  "$@" > out.txt 2> err.txt || status=$?
  [ "$status" = "$expected" ] || fail "exit status $status, expected $expected: $* ($(cat err.txt))"
}
# err_has TEXT: stderr of the last run contains TEXT (fixed string).
err_has() { grep -qF -- "$1" err.txt || fail "stderr lacks '$1': $(cat err.txt)"; }
out_has() { grep -qF -- "$1" out.txt || fail "stdout lacks '$1': $(head -c 2000 out.txt)"; }
# only_files A B ...: the work directory holds exactly these names (hidden ones included).
only_files() {
  want=$(printf '%s\n' out.txt err.txt "$@" | sort | tr '\n' ' ')
  got=$(ls -A | sort | tr '\n' ' ')
  [ "$want" = "$got" ] || fail "files: [$got], expected [$want]"
}
SCENES="$SOURCE_DIR/examples/scenes"
CART="$SCENES/cart_pole.json"
UPRIGHT="$SOURCE_DIR/examples/trajectories/cart_pole_upright.csv"
