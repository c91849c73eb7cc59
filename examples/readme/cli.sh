trellis=${TRELLIS:-build/cli/trellis}
$trellis info examples/scenes/cart_pole.json
$trellis linearize examples/scenes/cart_pole.json --compact          # A, B at the stored state
$trellis linearize tests/data/robots/panda.urdf --compact            # any URDF loads directly
$trellis equilibrium tests/data/robots/double_pendulum_continuous.urdf --hold --compact
$trellis gains tests/data/robots/double_pendulum_continuous.urdf --hold 5 --Q 10 --R 1 \
  --out "${TMPDIR:-/tmp}/hold_gains.csv"                              # TV-LQR about the held pose
