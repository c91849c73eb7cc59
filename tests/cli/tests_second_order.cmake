# tests/cli/tests_second_order.cmake — `trellis linearize --second-order` (issue 30). Included by
# tests/cli/CMakeLists.txt. The pendulum of examples/scenes/pendulum.json (m = l = 1, g = 9.81,
# damping 0.1, torque input) has θ̈ = −g sin θ − 0.1 θ̇ + u, whose only nonzero second derivative
# is ∂²θ̈/∂θ² = g sin θ = 2.8990532273… at θ = 0.3 (bounds 1e-9).
set(_so_pendulum "${_scenes}/pendulum.json")
set(_so_state "${_data}/pendulum_state_0_3.json")
trellis_mq_test(linearize.second_order.pendulum ARGS1 linearize --second-order --state "${_so_state}" "${_so_pendulum}"
  CHECKS1 "-DJSON=d2qdd_dqdq/0/0/0:GREATER:2.899053226&&d2qdd_dqdq/0/0/0:LESS:2.899053228&&d2qdd_dqddq/0/0/0:GREATER:-1e-12&&d2qdd_dqddq/0/0/0:LESS:1e-12&&d2qdd_ddqddq/0/0/0:GREATER:-1e-12&&d2qdd_ddqddq/0/0/0:LESS:1e-12&&d2qdd_dudq/0/0/0:GREATER:-1e-12&&d2qdd_dudq/0/0/0:LESS:1e-12&&d2qdd_duddq/0/0/0:GREATER:-1e-12&&d2qdd_duddq/0/0/0:LESS:1e-12&&d2qdd_dudu/0/0/0:GREATER:-1e-12&&d2qdd_dudu/0/0/0:LESS:1e-12&&A/1/0:GREATER:-9.371850959&&A/1/0:LESS:-9.371850957"
          -DSTDERR_EMPTY=ON)
# Every example scene (constraints of every kind among them) is accepted with --second-order.
file(GLOB _so_scenes CONFIGURE_DEPENDS "${_scenes}/*.json")
foreach(_scene IN LISTS _so_scenes)
  get_filename_component(_stem "${_scene}" NAME_WE)
  trellis_cli_test(linearize.second_order.example.${_stem}
    ARGS linearize --second-order --compact "${_scene}"
    CHECKS "-DSTDOUT_REGEX=\"status\":\"ok\".*\"d2qdd_dqdq\":...-?[0-9].*\"d2qdd_dudu\":" -DSTDERR_EMPTY=ON)
endforeach()
# A scene that includes a URDF (a revolute joint about a tilted axis, a prismatic one).
trellis_cli_test(linearize.second_order.urdf
  ARGS linearize --second-order --compact "${_data}/two_link_arm_scene.json"
  CHECKS "-DSTDOUT_REGEX=\"configs\":.\"shoulder\",\"slide\".*\"d2qdd_dqdq\":...-?[0-9]" -DSTDERR_EMPTY=ON)
# Along a trajectory: one line per knot, each with the tensors.
trellis_mq_test(linearize.second_order.trajectory
  ARGS1 linearize --second-order --trajectory "${PROJECT_SOURCE_DIR}/examples/trajectories/pendulum_swing.csv" "${_so_pendulum}"
  CHECKS1 -DLINES=81 "-DSTDOUT_REGEX=^.\"knot\":0,.*\"d2qdd_dudu\":...0(.0)?...\}\n" -DSTDERR_EMPTY=ON)
trellis_cli_test(linearize.second_order.help ARGS linearize --help
  CHECKS "-DSTDOUT_REGEX=--second-order.*d2qdd_dqdq" -DSTDERR_EMPTY=ON)
