# tests/cli/tests_optimize.cmake — `trellis optimize` (included by tests/cli/CMakeLists.txt).
if(NOT TARGET trellis_optimization)
  return()
endif()

set(_problems "${PROJECT_SOURCE_DIR}/examples/problems")
set(_optimize_dir "${CMAKE_CURRENT_BINARY_DIR}/optimize")
file(MAKE_DIRECTORY "${_optimize_dir}")

# Every example problem solves, prints the summary and writes the CSV.
file(GLOB _example_problems CONFIGURE_DEPENDS "${_problems}/*.json")
foreach(_problem IN LISTS _example_problems)
  get_filename_component(_stem "${_problem}" NAME_WE)
  trellis_cli_test(optimize.example.${_stem}
    ARGS optimize "${_problem}" --out "${_optimize_dir}/${_stem}.csv"
    CHECKS "-DSTDOUT_REGEX=status: solved\nipopt_status: Solve_Succeeded\niterations: [0-9]+\ncost: .*trajectory: .*${_stem}.csv"
           "-DSTDERR_REGEX=^iter +cost.*\n +1 ")
endforeach()

trellis_cli_test(optimize.trapezoidal_quiet
  ARGS optimize "${_problems}/cart_pole_swingup.json" --method trapezoidal --knots 21 --quiet
  CHECKS "-DSTDOUT_REGEX=status: solved.*knots: 21\nmethod: trapezoidal" -DSTDERR_EMPTY=ON)
trellis_cli_test(optimize.finite_difference
  ARGS optimize "${_problems}/cart_pole_swingup.json" --finite-difference --quiet
  CHECKS "-DSTDOUT_REGEX=status: solved.*derivatives: finite_difference" -DSTDERR_EMPTY=ON)
trellis_cli_test(optimize.help ARGS optimize --help
  CHECKS "-DSTDOUT_REGEX=usage: trellis optimize PROBLEM.json.*--out FILE" -DSTDERR_EMPTY=ON)

# An impossible bound: the cart must travel 1 m in 1 s with a 0.1 N push. Exit 3, the summary
# still printed, one line naming the infeasibility on stderr.
file(WRITE "${_optimize_dir}/infeasible.json" "{
  \"scene\": \"${PROJECT_SOURCE_DIR}/examples/scenes/cart_pole.json\",
  \"knots\": 11, \"horizon\": 1.0,
  \"initial_state\": {}, \"final_state\": {\"x\": 1.0},
  \"input_bounds\": {\"push\": [-0.1, 0.1]}
}
")
trellis_cli_test(optimize.infeasible
  ARGS optimize "${_optimize_dir}/infeasible.json" --quiet --out "${_optimize_dir}/infeasible.csv"
  CHECKS -DEXPECT_EXIT=3 "-DSTDOUT_REGEX=status: infeasible\nipopt_status: Infeasible_Problem_Detected"
         "-DSTDERR_REGEX=^trellis: optimize: infeasible .*local infeasibility[^\n]*\n$")

# Errors: exit 1 or 2, nothing on stdout, one line naming the problem.
set(_optimize_errors -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON)
file(WRITE "${_optimize_dir}/bad_field.json" "{
  \"scene\": \"${PROJECT_SOURCE_DIR}/examples/scenes/cart_pole.json\",
  \"horizon\": 2.0, \"input_bounds\": {\"force\": [-1, 1]}
}
")
trellis_cli_test(optimize.error.bad_field
  ARGS optimize "${_optimize_dir}/bad_field.json"
  CHECKS -DEXPECT_EXIT=1 ${_optimize_errors}
         "-DSTDERR_REGEX=bad_field.json: field 'input_bounds.force': unknown input 'force'")
trellis_cli_test(optimize.error.missing_file
  ARGS optimize "${_optimize_dir}/no_such_problem.json"
  CHECKS -DEXPECT_EXIT=1 ${_optimize_errors} "-DSTDERR_REGEX=no_such_problem.json: cannot open")
trellis_cli_test(optimize.error.missing_argument
  ARGS optimize
  CHECKS -DEXPECT_EXIT=2 ${_optimize_errors})
trellis_cli_test(optimize.error.bad_method
  ARGS optimize "${_problems}/cart_pole_swingup.json" --method euler
  CHECKS -DEXPECT_EXIT=2 ${_optimize_errors} "-DSTDERR_REGEX=--method: 'euler'")
