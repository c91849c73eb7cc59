# tests/cli/tests_optimize.cmake — `trellis optimize` (included by tests/cli/CMakeLists.txt).
if(NOT TARGET trellis_optimization)
  return()
endif()

set(_problems "${PROJECT_SOURCE_DIR}/examples/problems")
set(_optimize_dir "${CMAKE_CURRENT_BINARY_DIR}/optimize")
file(MAKE_DIRECTORY "${_optimize_dir}")

include("${CMAKE_CURRENT_LIST_DIR}/run_cli_files.cmake")

# Every example problem solves consistently (the a-posteriori check passes), prints the summary
# and writes the CSV. Then optimize → gains → simulate: the closed loop started exactly on a
# reference made consistent to 1e-6 of each state's range stays on it. Its deviation is the
# reference's remaining defect plus the integrators' error (simulate's CVODES at rtol 1e-8 over
# an unstable swing-up): measured max |x - x_ref| 5.2e-6 (cart-pole), 1.9e-5 (acrobot), 1.5e-6
# (paper pendulum) when the test was written; with a 1e-8 reference the acrobot's is 3.8e-6 (the
# integrators' floor); with the default 1e-3 reference 1.2e-3, 2.5e-3, 1.4e-3. The bound 1e-4
# leaves a margin of 5 and sits 10x below the default reference's deviation.
file(GLOB _example_problems CONFIGURE_DEPENDS "${_problems}/*.json")
foreach(_problem IN LISTS _example_problems)
  get_filename_component(_stem "${_problem}" NAME_WE)
  trellis_cli_test(optimize.example.${_stem}
    ARGS optimize "${_problem}" --out "${_optimize_dir}/${_stem}.csv"
    CHECKS "-DSTDOUT_REGEX=status: solved\nipopt_status: Solve_Succeeded\niterations: [0-9]+\ncost: .*consistency_defect: .*refinement_rounds: [0-9]+\nround_0: knots .*trajectory: .*${_stem}.csv"
           "-DSTDERR_REGEX=^iter +cost.*\n +1 ")
  file(READ "${_problem}" _problem_text)
  string(REGEX MATCH "\"scene\": \"([^\"]+)\"" _ "${_problem_text}")
  get_filename_component(_scene "${_problems}/${CMAKE_MATCH_1}" ABSOLUTE)
  trellis_cli_files_test(optimize.closed_loop.${_stem}
    ARGS1 optimize "${_problem}" --quiet --consistency-tol 1e-6 --out @WORK@/reference.csv
    CHECKS1 "-DSTDOUT_REGEX=status: solved" "-DNUMBERS=consistency_defect: :LESS:0.0000010001"
    ARGS2 gains "${_scene}" --trajectory @WORK@/reference.csv --Q 10 --R 0.1 --out @WORK@/gains.csv
    ARGS3 simulate "${_scene}" --trajectory @WORK@/reference.csv --gains @WORK@/gains.csv
          --out @WORK@/closed.csv
    CHECKS3 "-DNUMBERS=initial :LESS:0.000000000001&&, max :LESS:0.0001")
endforeach()

# Without refinement a coarse mesh is reported, not passed: exit 4, status inconsistent, the
# message names the state, the interval and the time; the CSV is still written.
trellis_cli_test(optimize.inconsistent
  ARGS optimize "${_problems}/cart_pole_swingup.json" --knots 8 --max-refinements 0 --quiet
       --out "${_optimize_dir}/inconsistent.csv"
  CHECKS -DEXPECT_EXIT=4 "-DSTDOUT_REGEX=status: inconsistent\nipopt_status: Solve_Succeeded.*consistency_where: [a-z]+ on interval [0-9]+ at t = .*refinement_rounds: 0"
         "-DSTDERR_REGEX=^trellis: optimize: inconsistent .*worst defect .* on interval [0-9]+ .*refinement limit 0[^\n]*\n$")

# Refinement from a coarse mesh: more knots, several rounds, solved.
trellis_cli_test(optimize.refined
  ARGS optimize "${_problems}/cart_pole_swingup.json" --knots 8 --quiet
  CHECKS "-DSTDOUT_REGEX=status: solved.*refinement_rounds: [1-9]\nround_0: knots 8, .*round_1: knots [1-9][0-9]+"
         -DSTDERR_EMPTY=ON)

# The final state of the closed chain fixed off the constraint manifold ("forgot free_final"):
# named before Ipopt runs, exit 1.
file(WRITE "${_optimize_dir}/off_manifold.json" "{
  \"scene\": \"${PROJECT_SOURCE_DIR}/examples/scenes/paper_pendulum.json\",
  \"knots\": 11, \"horizon\": 2.0,
  \"initial_state\": {\"theta1\": 0.5246, \"theta2\": 1.0451956794889683},
  \"final_state\": {\"theta1\": 1.2, \"theta2\": 0.5},
  \"free_initial\": [\"theta2\"]
}
")
trellis_cli_test(optimize.error.off_manifold
  ARGS optimize "${_optimize_dir}/off_manifold.json"
  CHECKS -DEXPECT_EXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON
         "-DSTDERR_REGEX=off_manifold.json: problem: the fixed final configuration violates constraint '[^']*' .row 0.: h = [-0-9.e]+ .*free_final")

trellis_cli_test(optimize.trapezoidal_quiet
  ARGS optimize "${_problems}/cart_pole_swingup.json" --method trapezoidal --knots 21 --quiet
  CHECKS "-DSTDOUT_REGEX=status: solved.*method: trapezoidal.*round_0: knots 21," -DSTDERR_EMPTY=ON)
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
         "-DSTDERR_REGEX=^trellis: optimize: infeasible: .*local infeasibility[^\n]*\n$")

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
# Radau IIA (L-stable, 3 stages): the same problem solved and consistent, the method named.
trellis_cli_test(optimize.method_radau
  ARGS optimize "${_problems}/cart_pole_swingup.json" --method radau --knots 21 --quiet
  CHECKS "-DSTDOUT_REGEX=status: solved.*method: radau.*round_0: knots 21," -DSTDERR_EMPTY=ON)

trellis_cli_test(optimize.error.bad_method
  ARGS optimize "${_problems}/cart_pole_swingup.json" --method euler
  CHECKS -DEXPECT_EXIT=2 ${_optimize_errors} "-DSTDERR_REGEX=--method: 'euler'")

# --json: the result's report (OptimizationResult::json: the status vocabulary's "status", "ok",
# "message", "t", "index" first) and the command's method, derivatives, trajectory, on one line;
# solved and not solved (exit 4, "ok": false, the message, the rounds and where the defect is).
trellis_cli_test(optimize.json
  ARGS optimize "${_problems}/cart_pole_swingup.json" --knots 8 --quiet --json
  CHECKS "-DSTDOUT_REGEX=^\\{\"status\":\"solved\",\"ok\":true,\"message\":\"\",\"t\":null,\"index\":null,\"ipopt_status\":\"Solve_Succeeded\",\"iterations\":[1-9][0-9]*,\"cost\":[-0-9.e]+,.*\"knots\":[1-9][0-9]+,\"hessian\":\"exact\",.*\"refinement_rounds\":[1-9],\"rounds\":\\[\\{\"knots\":8,.*\\}\\],\"solve_time_ms\":[0-9.e+-]+,\"solve_cpu_time_ms\":[0-9.e+-]+,\"evaluation_time_ms\":[0-9.e+-]+,\"hessian_time_ms\":[0-9.e+-]+,\"check_time_ms\":[0-9.e+-]+,\"method\":\"hermite_simpson\",\"derivatives\":\"exact\",\"trajectory\":null\\}\n$"
         -DSTDERR_EMPTY=ON)
trellis_cli_test(optimize.json_inconsistent
  ARGS optimize "${_problems}/cart_pole_swingup.json" --knots 8 --max-refinements 0 --quiet --json
  CHECKS -DEXPECT_EXIT=4 "-DSTDOUT_REGEX=^\\{\"status\":\"inconsistent\",\"ok\":false,\"message\":\"[^\"]*worst defect[^\"]*\",\"t\":[0-9.e+-]+,\"index\":[0-9]+,.*\"consistency_where\":\\{\"state\":\"[a-z]+\",\"interval\":[0-9]+,\"time\":[0-9.e+-]+\\},.*\"refinement_rounds\":0,.*\\}\n$"
         "-DSTDERR_REGEX=^trellis: optimize: inconsistent ")
