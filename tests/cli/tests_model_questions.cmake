# tests/cli/tests_model_questions.cmake — the commands that ask questions of a model: `info`,
# `linearize --state/--trajectory`, `kinematics`, `project`, `equilibrium`, `inverse-dynamics`.
# Included by tests/cli/CMakeLists.txt (_scenes, _data, trellis_cli_test). Expected numbers are
# closed forms of the pendulum of examples/scenes/pendulum.json (m = 1, l = 1, g = 9.81, damping
# 0.1, torque input): the bounds bracket each value by 1e-9 unless said otherwise.
include("${CMAKE_CURRENT_LIST_DIR}/run_model_questions.cmake")
set(_pendulum "${_scenes}/pendulum.json")
set(_paper "${_scenes}/paper_pendulum.json")
set(_cart_pole "${_scenes}/cart_pole.json")
set(_swing "${PROJECT_SOURCE_DIR}/examples/trajectories/pendulum_swing.csv")
set(_state03 "${_data}/pendulum_state_0_3.json")
set(_error_checks -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON)

# ---- info ---------------------------------------------------------------------------------------
trellis_cli_test(info.pendulum_text ARGS info "${_pendulum}"
  CHECKS "-DSTDOUT_REGEX=n = 1 configuration variables, m = 1 inputs.*theta: rz of frame 'pivot'.*torque: config_force on theta.*world -> pivot: joint theta.*pivot -> bob: fixed, body theta.*theta: m = 1, com \\[0, -1, 0\\].*tangent space at the scene's state: dimension 2 of 2"
         -DSTDERR_EMPTY=ON)
# The paper's pendulum: one distance constraint, so d = 2n - 2 = 2 of 4 at its (consistent) state.
trellis_mq_test(info.paper_json ARGS1 info --json "${_paper}"
  CHECKS1 "-DJSON=n:GREATER:1.5&&n:LESS:2.5&&nc:GREATER:0.5&&nc:LESS:1.5&&tangent/dimension:GREATER:1.5&&tangent/dimension:LESS:2.5"
          "-DSTDOUT_REGEX=\"constraints\": .\\{\"name\":\"constraints.0. \\(distance B"
          -DSTDERR_EMPTY=ON)
# A skate (tests/cli/data/skate.json): one nonholonomic row, so d = 2n - 1 = 5.
trellis_cli_test(info.knife_edge_nonholonomic ARGS info "${_data}/skate.json"
  CHECKS "-DSTDOUT_REGEX=knife_edge blade\\): nonholonomic.*dimension 5 of 6")

# ---- linearize at a state and along a trajectory -------------------------------------------------
# A[1][0] = -g cos(0.3) = -9.371850958, A[1][1] = -c = -0.1; the state file sets theta and dtheta.
trellis_mq_test(linearize.state_file ARGS1 linearize --state "${_state03}" "${_pendulum}"
  CHECKS1 "-DJSON=A/1/0:GREATER:-9.371850959&&A/1/0:LESS:-9.371850957&&A/1/1:GREATER:-0.1000000001&&A/1/1:LESS:-0.0999999999&&dq/0:GREATER:0.4999999999&&dq/0:LESS:0.5000000001"
          -DSTDERR_EMPTY=ON)
# One JSON object per knot and line (81 knots).
trellis_mq_test(linearize.trajectory ARGS1 linearize --trajectory "${_swing}" "${_pendulum}"
  CHECKS1 -DLINES=81 "-DSTDOUT_REGEX=^\\{\"knot\":0,\"t\":0(\\.0)?,\"status\":\"ok\".*\n\\{\"knot\":80,"
          -DSTDERR_EMPTY=ON)
trellis_cli_test(linearize.error.unknown_state_name
  ARGS linearize --state "${_data}/pendulum_state_unknown.json" "${_pendulum}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=pendulum_state_unknown.json: state: field 'q.phi': unknown configuration variable \"phi\" \\(known: theta\\)")
trellis_cli_test(linearize.error.state_and_trajectory
  ARGS linearize --state "${_state03}" --trajectory "${_swing}" "${_pendulum}"
  CHECKS -DEXPECT_EXIT=2 ${_error_checks} "-DSTDERR_REGEX=not both")
trellis_cli_test(linearize.error.trajectory_names
  ARGS linearize --trajectory "${_swing}" "${_paper}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=pendulum_swing.csv does not match the scene")

# ---- kinematics ---------------------------------------------------------------------------------
# bob at theta = 0.3: (sin 0.3, -cos 0.3, 0), orientation rz(0.3): qw = cos 0.15, qz = sin 0.15.
trellis_mq_test(kinematics.state ARGS1 kinematics --state "${_state03}" --frames bob "${_pendulum}"
  CHECKS1 -DLINES=2 "-DSTDOUT_REGEX=^t,bob.x,bob.y,bob.z,bob.qw,bob.qx,bob.qy,bob.qz\n"
          "-DCSV=0/bob.x:GREATER:0.2955202065&&0/bob.x:LESS:0.2955202068&&0/bob.y:GREATER:-0.9553364892&&0/bob.y:LESS:-0.9553364890&&0/bob.qw:GREATER:0.9887710778&&0/bob.qw:LESS:0.9887710780&&0/bob.qz:GREATER:0.1494381324&&0/bob.qz:LESS:0.1494381326")
trellis_mq_test(kinematics.matrix ARGS1 kinematics --state "${_state03}" --frames pivot --rotation matrix "${_pendulum}"
  CHECKS1 "-DSTDOUT_REGEX=^t,pivot.x,pivot.y,pivot.z,pivot.R00,pivot.R01,pivot.R02,pivot.R10,"
          "-DCSV=0/pivot.R01:GREATER:-0.2955202068&&0/pivot.R01:LESS:-0.2955202065")
trellis_mq_test(kinematics.trajectory ARGS1 kinematics --trajectory "${_swing}" "${_pendulum}"
  CHECKS1 -DLINES=82 "-DSTDOUT_REGEX=^t,pivot.x,.*,bob.qz\n0,")
trellis_cli_test(kinematics.error.unknown_frame ARGS kinematics --frames bob,nose "${_pendulum}"
  CHECKS -DEXPECT_EXIT=2 ${_error_checks} "-DSTDERR_REGEX=unknown frame 'nose' \\(known: pivot, bob\\)")

# ---- project ------------------------------------------------------------------------------------
# The paper's stored state is off its constraint (h = -3.47e-3, docs/paper_errata.md): projected, |h| and
# |A q'| are at rounding level, and the linearization at the projected state (read back through
# --state) sees the same.
trellis_mq_test(project.paper_then_linearize
  ARGS1 project "${_paper}"
  CHECKS1 "-DJSON=h_before:GREATER:3e-3&&h_after:LESS:1e-12&&velocity_after:LESS:1e-12" -DSAVE_JSON=state -DSTDERR_EMPTY=ON
  ARGS2 linearize --state @WORK@/state.json "${_paper}"
  CHECKS2 "-DJSON=h/0:LESS:1e-12&&h/0:GREATER:-1e-12&&hdot/0:LESS:1e-12&&hdot/0:GREATER:-1e-12")
trellis_mq_test(project.fixed_coordinate ARGS1 project --fix theta1 "${_paper}"
  CHECKS1 "-DJSON=q/0:GREATER:0.52459999999&&q/0:LESS:0.52460000001&&h_after:LESS:1e-12")
# The skate's velocity violates its knife edge slightly: only q' changes (no holonomic rows).
trellis_mq_test(project.knife_edge_velocity ARGS1 project "${_data}/skate.json"
  CHECKS1 "-DJSON=velocity_before:GREATER:1e-4&&velocity_after:LESS:1e-14&&iterations:LESS:0.5&&q/2:GREATER:0.39999999999&&q/2:LESS:0.40000000001")
trellis_cli_test(project.error.unknown_fixed ARGS project --fix theta3 "${_paper}"
  CHECKS -DEXPECT_EXIT=2 ${_error_checks} "-DSTDERR_REGEX=unknown configuration variable 'theta3'")

# ---- equilibrium --------------------------------------------------------------------------------
# Under a torque of 2: theta = asin(2 / 9.81) = 0.2053130024; damped, so asymptotically stable.
trellis_mq_test(equilibrium.pendulum_torque ARGS1 equilibrium --inputs torque=2 "${_pendulum}"
  CHECKS1 "-DJSON=q/0:GREATER:0.2053130023&&q/0:LESS:0.2053130025&&qdd_residual:LESS:1e-10&&max_real_eigenvalue:LESS:0"
          -DSTDERR_EMPTY=ON)
# Holding theta = 0.3 takes g sin 0.3 = 2.899053227.
trellis_mq_test(equilibrium.hold ARGS1 equilibrium --hold --state "${_state03}" "${_pendulum}"
  CHECKS1 "-DJSON=u/0:GREATER:2.899053226&&u/0:LESS:2.899053228&&residual:LESS:1e-12")
trellis_cli_test(equilibrium.error.no_equilibrium ARGS equilibrium --inputs torque=20 "${_pendulum}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=no equilibrium found \\(not_converged\\)")
# The cart-pole's push cannot hold the pole tilted (the state file sets theta = 0.3).
trellis_cli_test(equilibrium.error.cannot_hold ARGS equilibrium --hold --state "${_state03}" "${_cart_pole}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=the pose cannot be held \\(unreachable\\)")
trellis_cli_test(equilibrium.error.unknown_input ARGS equilibrium --inputs force=2 "${_pendulum}"
  CHECKS -DEXPECT_EXIT=2 ${_error_checks} "-DSTDERR_REGEX=unknown input 'force' \\(known: torque\\)")

# ---- inverse dynamics ---------------------------------------------------------------------------
# u = q'' + g sin(theta) + c q': 2.899053227 at rest, 4.949053227 at q' = 0.5, q'' = 2.
trellis_mq_test(inverse_dynamics.pendulum_trajectory
  ARGS1 inverse-dynamics --trajectory "${_data}/pendulum_accelerations.csv" "${_pendulum}"
  CHECKS1 -DLINES=3 "-DSTDOUT_REGEX=^t,torque,residual,constraint_residual,status\n"
          "-DCSV=0/torque:GREATER:2.899053226&&0/torque:LESS:2.899053228&&1/torque:GREATER:4.949053226&&1/torque:LESS:4.949053228")
# The cart-pole cannot hold its pole at 0.2 rad at rest: an error, or with --allow-residual the
# least-squares force (0: the push cannot help) and the residual m g l sin(0.2) = 0.0974 N m.
trellis_cli_test(inverse_dynamics.error.unreachable
  ARGS inverse-dynamics --trajectory "${_data}/cart_pole_accelerations.csv" "${_cart_pole}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=knot 0 \\(t = 0\\): unreachable")
trellis_mq_test(inverse_dynamics.allow_residual
  ARGS1 inverse-dynamics --allow-residual --trajectory "${_data}/cart_pole_accelerations.csv" "${_cart_pole}"
  CHECKS1 "-DSTDOUT_REGEX=,unreachable\n$"
          "-DCSV=0/push:LESS:1e-12&&0/push:GREATER:-1e-12&&0/residual:GREATER:0.097447&&0/residual:LESS:0.097448")
trellis_cli_test(inverse_dynamics.error.header
  ARGS inverse-dynamics --trajectory "${_swing}" "${_pendulum}"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks} "-DSTDERR_REGEX=the header must be 't,theta,dtheta,ddtheta'")
