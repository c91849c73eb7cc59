# tests/cli/tests_urdf.cmake — URDFs as people have them (issue 27 parts 3 and 4): an undeclared
# 'world' parent, Coulomb friction refused or ignored with a warning, floating bases held only by
# contacts, equilibria checked against the joint limits, effort as input bounds.
set(_urdf "${_data}/urdf")
set(_robots "${PROJECT_SOURCE_DIR}/tests/data/robots")

trellis_cli_test(urdf.friction_refused ARGS info "${_urdf}/friction_arm.urdf"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks}
  "-DSTDERR_REGEX=friction_arm.urdf:10: joint 'shoulder': <dynamics> attribute 'friction': value '0.3': Coulomb friction is not modelled.*ignore_friction")
# Read through a scene with ignore_friction: the undeclared 'world' is the world, the friction a warning.
trellis_cli_test(urdf.friction_ignored_world_parent ARGS info "${_urdf}/friction_arm_ignored.json"
  CHECKS "-DSTDOUT_REGEX=n = 2 configuration variables, m = 2 inputs.*world -> base_link: fixed, body world, at \\[0, 0, 2\\]"
  "-DSTDERR_REGEX=^trellis: warning: .*friction_arm.urdf:10: joint 'shoulder': <dynamics> attribute 'friction': value '0.3': Coulomb friction ignored \\(ignore_friction\\)\n$")
# Hanging down (q = 0) is inside the limits; from shoulder = 3 the search ends beyond them.
trellis_cli_test(urdf.equilibrium_inside_limits ARGS equilibrium "${_urdf}/friction_arm_ignored.json"
  CHECKS "-DSTDOUT_REGEX=\"outside_limits\": ..\n")
trellis_cli_test(urdf.equilibrium_outside_limits
  ARGS equilibrium --state "${_urdf}/arm_start_out.json" "${_urdf}/friction_arm_ignored.json"
  CHECKS -DEXPECT_EXIT=1 -DSTDOUT_EMPTY=ON
  "-DSTDERR_REGEX=the equilibrium found lies outside the URDF joint limits: shoulder = 3.14159 \\(limits \\[-1, 1\\]\\).*--ignore-limits")
trellis_cli_test(urdf.equilibrium_ignore_limits
  ARGS equilibrium --ignore-limits --state "${_urdf}/arm_start_out.json" "${_urdf}/friction_arm_ignored.json"
  CHECKS "-DSTDOUT_REGEX=\"outside_limits\": .\"shoulder = 3.14159 \\(limits .-1, 1.\\)\"")
# Holding the arm up needs ~8 N m at the shoulder: more than its effort limit of 5.
trellis_cli_test(urdf.hold_effort_bounds
  ARGS equilibrium --hold --effort-bounds --state "${_urdf}/arm_up.json" "${_urdf}/friction_arm_ignored.json"
  CHECKS -DEXPECT_EXIT=1 -DSTDOUT_EMPTY=ON "-DSTDERR_REGEX=cannot be held \\(input_bounds\\).*shoulder")
trellis_cli_test(urdf.hold_no_effort_bounds
  ARGS equilibrium --hold --state "${_urdf}/arm_up.json" "${_urdf}/friction_arm_ignored.json"
  CHECKS "-DSTDOUT_REGEX=\"status\": \"ok\"")
# A floating base: refused without contacts, with the reason; held with the overlay's contacts.
trellis_cli_test(urdf.floating_hold_without_contacts ARGS equilibrium --hold "${_urdf}/solo12_floating.json"
  CHECKS -DEXPECT_EXIT=1 ${_error_checks}
  "-DSTDERR_REGEX=cannot be held \\(unreachable\\).*no input and no constraint acts on floating_base.x, .*floating_base.roll, yet the pose needs a generalized force of up to 24.5[0-9]* on floating_base.z.*a floating base without contacts cannot be held.*Floating bases and contacts")
trellis_cli_test(urdf.floating_gains_without_contacts ARGS gains "${_urdf}/solo12_floating.json" --hold 1 --out "${CMAKE_CURRENT_BINARY_DIR}/never_written.csv"
  CHECKS -DEXPECT_EXIT=1 -DSTDOUT_EMPTY=ON "-DSTDERR_REGEX=unreachable")
trellis_cli_test(urdf.floating_hold_with_contacts ARGS equilibrium --hold --compact "${_robots}/solo12_standing.json"
  CHECKS "-DSTDOUT_REGEX=\"status\":\"ok\".*\"inputs\":.\"FL_HAA\"" -DSTDERR_EMPTY=ON)
# Balancing a floating-base robot from the command line alone (issue 27's "done when"): Solo12 with
# its four feet held by the overlay's point contacts, the infinite-horizon gain at 100 Hz on the
# 12-dimensional constraint manifold (every row K_inf), then the loop about the held pose from a
# seeded random start (|x - x_ref| 0.214 at t = 0) brought back: measured final 1.5e-3 after 5 s
# (bound 1e-2), the contacts kept (drift after the first projection ~1e-10, bound 1e-6).
trellis_cli_files_test(urdf.floating_balances_at_100hz
  ARGS1 gains "${_robots}/solo12_standing.json" --hold 5 --rate 100 --Q 10 --infinite-horizon --out @WORK@/gains.csv
  CHECKS1 -DSTDERR_EMPTY=ON
          "-DSTDOUT_REGEX=on the constraint manifold \\(tangent dimension 12 of 36.*infinite horizon: Qf = S_inf of the DARE: ok.*rank 12 of 12 \\(controllable\\)"
          "-DNUMBERS=/ \\|K_inf\\| :LESS:1e-10"
  ARGS2 simulate "${_robots}/solo12_standing.json" --hold 5 --rate 100 --gains @WORK@/gains.csv
        --perturb-random 0.01 --seed 3 --out @WORK@/closed.csv
  CHECKS2 -DSTDERR_EMPTY=ON "-DSTDOUT_REGEX=feedback sampled at 100 Hz, feed-forward uff_k from the gain file"
          "-DNUMBERS=initial :GREATER:0.1&&final :LESS:1e-2&&max at later output times :LESS:1e-6")
