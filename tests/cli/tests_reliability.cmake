# tests/cli/tests_reliability.cmake — issue 15: no command exits 0 with a missing, partial or
# invalid result. One or more tests per class of failure, each checking the exit status, the
# message (it names the input) and that no partial or temporary file is left (run_cli_reliability).
# Included by tests/cli/CMakeLists.txt (_scenes, _data).
set(_rel_runner "${CMAKE_CURRENT_LIST_DIR}/run_cli_reliability.cmake")
set(_rel_traj "${PROJECT_SOURCE_DIR}/examples/trajectories")
set(_rel_cart "${_scenes}/cart_pole.json")
set(_rel_upright "${_rel_traj}/cart_pole_upright.csv")
set(_rel_gains "${_data}/cart_pole_zero_gains.csv")

# trellis_reliability_test(NAME ARGS <args...> [CHECKS <-Dvar=value...>])
function(trellis_reliability_test name)
  cmake_parse_arguments(PARSE_ARGV 1 T "" "" "ARGS;CHECKS")
  string(REPLACE ";" "|" _args "${T_ARGS}")
  add_test(NAME cli.reliability.${name}
    COMMAND ${CMAKE_COMMAND} "-DTRELLIS=$<TARGET_FILE:trellis>" "-DARGS=${_args}"
            "-DWORK=${CMAKE_CURRENT_BINARY_DIR}/cli_work/reliability.${name}" ${T_CHECKS}
            -P "${_rel_runner}")
  set_tests_properties(cli.reliability.${name} PROPERTIES LABELS cli SKIP_REGULAR_EXPRESSION "SKIPPED:")
endfunction()

set(_fail -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON)
set(_gains gains "${_rel_cart}" --trajectory "${_rel_upright}")
set(_simulate simulate "${_rel_cart}" --trajectory "${_rel_upright}" --gains "${_rel_gains}")

# ---- failed writes: the output is complete or absent, with the path and the OS error ---------
trellis_reliability_test(write.dev_full
  ARGS ${_gains} --out /dev/full
  CHECKS ${_fail} "-DSTDERR_REGEX=/dev/full: write failed \\(No space left on device\\)" -DCHECK_DEV_FULL=ON)
trellis_reliability_test(write.missing_directory
  ARGS ${_gains} --out @WORK@/no/such/dir/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=gains.csv: cannot write: the directory '.*no/such/dir' is not accessible \\(No such file or directory\\)")
trellis_reliability_test(write.read_only_directory
  ARGS ${_simulate} --out @WORK@/ro/closed.csv
  CHECKS ${_fail} -DREAD_ONLY_DIR=ro "-DSTDERR_REGEX=closed.csv: cannot create a file in .*ro.*Permission denied")
trellis_reliability_test(write.directory_as_output
  ARGS ${_gains} --out @WORK@
  CHECKS ${_fail} "-DSTDERR_REGEX=: is a directory \\(expected a file name to write\\)")
# Under a file-size limit the write fails with EFBIG (SIGXFSZ ignored), the temporary is removed.
trellis_reliability_test(write.file_size_limit
  ARGS ${_gains} --dt 0.0005 --out @WORK@/gains.csv
  CHECKS ${_fail} -DULIMIT_F=8 "-DSTDERR_REGEX=gains.csv: write failed \\(File too large\\)")
trellis_reliability_test(write.optimize_out
  ARGS optimize "${PROJECT_SOURCE_DIR}/examples/problems/cart_pole_swingup.json" --knots 5 --max-iter 1
       --quiet --out @WORK@/missing/traj.csv
  CHECKS "-DSTDERR_REGEX=traj.csv: cannot write: the directory .*missing' is not accessible")

# ---- unbounded work: sizes that input controls are checked up front ---------------------------
trellis_reliability_test(size.gains_dt
  ARGS ${_gains} --dt 1e-12 --out @WORK@/gains.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--dt: a step of 1e-12 over 3 gives 3e\\+12 output rows; the limit is 1000000")
trellis_reliability_test(size.simulate_output_step
  ARGS ${_simulate} --output-step 1e-9 --out @WORK@/closed.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--output-step: .*output rows; the limit is")
trellis_reliability_test(size.simulate_rate
  ARGS ${_simulate} --rate 1e300 --out @WORK@/closed.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--rate: .*feedback samples; the limit is")
set(_gains_zero gains "${_rel_cart}" --trajectory /dev/zero --out @WORK@/gains.csv)
trellis_reliability_test(size.trajectory_dev_zero
  ARGS ${_gains_zero}
  CHECKS ${_fail} "-DSTDERR_REGEX=/dev/zero: line 1 is longer than 1048576 characters")
trellis_reliability_test(size.gains_dev_zero
  ARGS simulate "${_rel_cart}" --trajectory "${_rel_upright}" --gains /dev/zero --out @WORK@/closed.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=/dev/zero: line 1 is longer than 1048576 characters")
trellis_reliability_test(size.chain_scene
  ARGS linearize @WORK@/generated.json
  CHECKS ${_fail} -DGENERATE=chain:1200 "-DSTDERR_REGEX=frame 'l1001': field 'config': the scene has more than 1000 configuration variables")
trellis_reliability_test(size.wide_scene
  ARGS linearize @WORK@/generated.json
  CHECKS ${_fail} -DGENERATE=flat:1500 "-DSTDERR_REGEX=frame 'l1001'.*more than 1000 configuration variables.*200 n\\^2 bytes")
trellis_reliability_test(size.problem_knots
  ARGS optimize "${_data}/problem_knots_wrap.json"
  CHECKS ${_fail} "-DSTDERR_REGEX=problem_knots_wrap.json: field 'knots': 4294967298 is out of the range \\[2, 100000\\]")

# ---- silently invalid results become errors naming what failed --------------------------------
trellis_reliability_test(invalid.reference_off_constraint
  ARGS gains "${_scenes}/paper_pendulum.json" --trajectory "${_data}/paper_pendulum_off_constraint.csv"
       --out @WORK@/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=paper_pendulum_off_constraint.csv: row 1 \\(t = 0\\) violates the constraint '.*' of .*paper_pendulum.json: h\\(q\\) = ")
trellis_reliability_test(invalid.simulate_reference_off_constraint
  ARGS simulate "${_scenes}/paper_pendulum.json" --trajectory "${_data}/paper_pendulum_off_constraint.csv"
       --gains "${_data}/paper_pendulum_zero_gains.csv" --out @WORK@/closed.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=row 1 \\(t = 0\\) violates the constraint")
trellis_reliability_test(invalid.distance_zero
  ARGS linearize "${_data}/distance_zero.json"
  CHECKS ${_fail} "-DSTDERR_REGEX=distance_zero.json: constraints\\[0\\].*field 'distance': 0 must be > 0")
trellis_reliability_test(invalid.gains_atol
  ARGS ${_gains} --atol 1e300 --out @WORK@/gains.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--atol: 1e300 is outside \\[1e-20, 1\\]")
trellis_reliability_test(invalid.simulate_rtol
  ARGS ${_simulate} --rtol 0.5 --out @WORK@/closed.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--rtol: 0.5 is outside \\[1e-14, 0.1\\]")

# ---- counts that would wrap around are refused with their range -------------------------------
trellis_reliability_test(count.max_iter
  ARGS optimize "${PROJECT_SOURCE_DIR}/examples/problems/cart_pole_swingup.json" --max-iter 4294967296
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--max-iter: '4294967296' is out of the range \\[0, 2147483647\\]")
trellis_reliability_test(count.max_steps
  ARGS ${_gains} --max-steps 18446744073709551615 --out @WORK@/gains.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--max-steps: '18446744073709551615' is out of the range \\[1, 9223372036854775807\\]")
trellis_reliability_test(count.seed_negative
  ARGS ${_simulate} --perturb-random 0.1 --seed -1 --out @WORK@/closed.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--seed: '-1' is out of the range \\[0, 18446744073709551615\\]")
trellis_reliability_test(count.knots_option
  ARGS optimize "${PROJECT_SOURCE_DIR}/examples/problems/cart_pole_swingup.json" --knots 4294967298
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=--knots: '4294967298' is out of the range \\[2, 100000\\]")

# ---- overflow to inf: a perturbed start that is not finite is bad input -----------------------
trellis_reliability_test(overflow.perturb_sum
  ARGS ${_simulate} --perturb theta=1.7e308 --perturb-random 1e308 --out @WORK@/closed.csv
  CHECKS -DEXPECT_EXIT=2 ${_fail} "-DSTDERR_REGEX=the perturbed start .* is not finite")

# ---- messages that name the input --------------------------------------------------------------
trellis_reliability_test(message.weight_directory
  ARGS ${_gains} --Q "${_data}" --out @WORK@/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=--Q: .*data: is a directory, not a weight file")
trellis_reliability_test(message.weight_overflow
  ARGS ${_gains} --Q "${_data}/weights_overflow.json" --out @WORK@/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=weights_overflow.json' is not valid JSON: number overflow parsing '1e999'")
trellis_reliability_test(message.problem_overflow
  ARGS optimize "${_data}/problem_overflow.json"
  CHECKS ${_fail} "-DSTDERR_REGEX=problem_overflow.json: invalid JSON: .*1e999")
trellis_reliability_test(message.problem_directory
  ARGS optimize "${_data}"
  CHECKS ${_fail} "-DSTDERR_REGEX=data: is a directory, not a problem file")
trellis_reliability_test(message.trajectory_directory
  ARGS gains "${_rel_cart}" --trajectory "${_data}" --out @WORK@/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=data: is a directory, not a trajectory CSV file")
trellis_reliability_test(message.missing_velocity_column
  ARGS gains "${_rel_cart}" --trajectory "${_data}/cart_pole_missing_dtheta.csv" --out @WORK@/gains.csv
  CHECKS ${_fail} "-DSTDERR_REGEX=cart_pole_missing_dtheta.csv: line 1: missing the velocity column 'dtheta'")

# ---- a scene without inputs linearizes (B is 2n x 0; clang's UBSan checks the block offsets) ---
trellis_reliability_test(no_inputs
  ARGS linearize --compact "${_data}/no_inputs.json"
  CHECKS -DEXPECT_EXIT=0 "-DSTDOUT_REGEX=\"status\":\"ok\".*\"B\":\\[\\[\\],\\[\\]\\]")
