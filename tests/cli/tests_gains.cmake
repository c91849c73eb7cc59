# tests/cli/tests_gains.cmake — `trellis gains` (and, to show a gain stabilizes, `trellis simulate`).
# Included by tests/cli/CMakeLists.txt (_scenes, _data, trellis_cli_test).
include("${CMAKE_CURRENT_LIST_DIR}/run_cli_files.cmake")
set(_trajectories "${PROJECT_SOURCE_DIR}/examples/trajectories")
set(_cart_pole "${_scenes}/cart_pole.json")
set(_cart_pole_upright "${_trajectories}/cart_pole_upright.csv")
set(_paper "${_scenes}/paper_pendulum.json")
set(_paper_swing "${_trajectories}/paper_pendulum_swing.csv")
# The first line is the metadata (m, 2n, continuous or the sample rate); FILE_ROWS counts the
# named header t,K[<input>|<state>],... (and uff[<input>] with --rate) and the data rows.
set(_gain_header "# trellis gain schedule: m=1 nx=4 continuous .*")

# ---- success ----------------------------------------------------------------------------------
# Cart-pole held upright for 3 s (31 knots): one gain row per knot. The gain must stabilize the
# nonlinear closed loop: from a 0.1 rad tilt the final error |x - x_ref| is below 0.005 (measured
# 0.0017: the LQR's closed-loop poles decay well within 3 s; the bound leaves a factor 3 and is still
# 20x below the perturbation). Step 3 is the control that shows the check can fail: with K = 0 the
# pole falls (final error measured 7.9, bound > 0.1).
trellis_cli_files_test(gains.cart_pole_upright_stabilizes
  ARGS1 gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --Q 10,10,1,1 --R 0.1
        --out @WORK@/gains.csv
  CHECKS1 -DFILE=@WORK@/gains.csv "-DFILE_HEADER=${_gain_header}" -DFILE_ROWS=32 -DSTDERR_EMPTY=ON
          "-DSTDOUT_REGEX=wrote .*gains.csv: 31 rows of K \\(1 x 4\\).*riccati: full state.*steps.*S: min eigenvalue [0-9].*controllability at t = 0: rank 4 of 4 \\(controllable\\).*gramian on \\[0, 3\\]: max eigenvalue [0-9.e+]+; min eigenvalue not computed"
  ARGS2 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}" --gains @WORK@/gains.csv
        --perturb theta=0.1 --out @WORK@/closed.csv
  CHECKS2 -DFILE=@WORK@/closed.csv "-DFILE_HEADER=t,x,theta,dx,dtheta,push" -DFILE_ROWS=31
          "-DNUMBERS=initial :GREATER:0.0999999&&initial :LESS:0.1000001&&final :LESS:0.005"
  ARGS3 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}"
        --gains "${_data}/cart_pole_zero_gains.csv" --perturb theta=0.1 --out @WORK@/open.csv
  CHECKS3 "-DNUMBERS=final :GREATER:0.1")

# --dt: a uniform grid 0, 0.25, ..., 2.75 and the end time 3 (13 rows); a full Q from a JSON file.
trellis_cli_files_test(gains.uniform_grid_and_weight_file
  ARGS1 gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --dt 0.25
        --Q "${_data}/weights_cart_pole_Q.json" --R 0.1 --Qf 1 --method factored --out @WORK@/gains.csv
  CHECKS1 -DFILE=@WORK@/gains.csv "-DFILE_HEADER=${_gain_header}" -DFILE_ROWS=14
          "-DSTDOUT_REGEX=13 rows of K.*riccati: factored")

# The paper's constrained pendulum (one distance constraint: 2n = 4, tangent dimension 2) along a
# swing that satisfies its dynamics: the manifold path. The closed loop from a 0.05 rad error in
# theta1 (projected onto the constraints: initial error 0.051) ends below 0.005 (measured 0.0011,
# a factor 4 of margin) and, projected, the drift after the start stays below 1e-6 (the dynamics
# keep the constraints to the integrator's tolerance); the control with K = 0 ends at 0.27
# (bound > 0.1).
trellis_cli_files_test(gains.paper_pendulum_manifold
  ARGS1 gains "${_paper}" --trajectory "${_paper_swing}" --R 0.01 --out @WORK@/gains.csv
  CHECKS1 -DFILE=@WORK@/gains.csv "-DFILE_HEADER=${_gain_header}" -DFILE_ROWS=42 -DSTDERR_EMPTY=ON
          "-DSTDOUT_REGEX=riccati: on the constraint manifold \\(tangent dimension 2 of 4.*Sr: min eigenvalue.*rank 2 of 2 \\(controllable\\)"
  ARGS2 simulate "${_paper}" --trajectory "${_paper_swing}" --gains @WORK@/gains.csv
        --perturb theta1=0.05 --out @WORK@/closed.csv
  CHECKS2 -DFILE=@WORK@/closed.csv "-DFILE_HEADER=t,theta1,theta2,dtheta1,dtheta2,u" -DFILE_ROWS=41
          "-DNUMBERS=initial :GREATER:0.04&&final :LESS:0.005&&max at later output times :LESS:1e-6"
  ARGS3 simulate "${_paper}" --trajectory "${_paper_swing}"
        --gains "${_data}/paper_pendulum_zero_gains.csv" --perturb theta1=0.05 --out @WORK@/open.csv
  CHECKS3 "-DNUMBERS=final :GREATER:0.1"
  # The same closed loop by Radau IIA (--method radau): the same bounds.
  ARGS4 simulate "${_paper}" --trajectory "${_paper_swing}" --gains @WORK@/gains.csv
        --perturb theta1=0.05 --method radau --out @WORK@/radau.csv
  CHECKS4 -DFILE=@WORK@/radau.csv -DFILE_ROWS=41
          "-DNUMBERS=initial :GREATER:0.04&&final :LESS:0.005&&max at later output times :LESS:1e-6")

# ---- sampled (zero-order-hold) gains --------------------------------------------------------------
# --rate 50 on the 3 s upright reference: gains at the 150 sample times 0, 0.02, ..., 2.98 and at T
# (151 rows + the named header), the file and the summary say they are ZOH gains at 50 Hz. Applied
# at 50 Hz with |push| <= 3 N from a 0.1 rad tilt the loop recovers (final error < 0.01); applied
# continuously they are refused (exit 1, naming the rate to use).
trellis_cli_files_test(gains.sampled_50hz
  ARGS1 gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --Q 10,10,1,1 --R 0.1 --rate 50
        --out @WORK@/gains.csv
  CHECKS1 -DFILE=@WORK@/gains.csv "-DFILE_HEADER=# trellis gain schedule: m=1 nx=4 sample_rate_hz=50 .*"
          -DFILE_ROWS=152 -DSTDERR_EMPTY=ON
          "-DSTDOUT_REGEX=wrote .*gains.csv: 151 rows of K \\(1 x 4\\) on \\[0, 3\\], zero-order-hold gains for a controller sampling at 50 Hz.*riccati: sampled-zoh.*controllable"
  ARGS2 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}" --gains @WORK@/gains.csv
        --perturb theta=0.1 --rate 50 --umin -3 --umax 3 --out @WORK@/closed.csv
  CHECKS2 -DSTDERR_EMPTY=ON "-DSTDOUT_REGEX=feedback sampled at 50 Hz" "-DNUMBERS=final :LESS:0.01"
  ARGS3 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}" --gains @WORK@/gains.csv
        --perturb theta=0.1 --out @WORK@/continuous.csv
  CHECKS3 -DEXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON
          "-DSTDERR_REGEX=zero-order-hold gains for a controller sampling at 50 Hz cannot be applied continuously: sample at 50 Hz")
# Discrete gains at another rate: refused; continuous gains at a rate: a warning on stderr.
trellis_cli_files_test(gains.sampled_rate_mismatch
  ARGS1 gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --Q 10,10,1,1 --R 0.1 --rate 50
        --out @WORK@/sampled.csv
  ARGS2 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}" --gains @WORK@/sampled.csv
        --rate 100 --out @WORK@/closed.csv
  CHECKS2 -DEXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON
          "-DSTDERR_REGEX=gains for 50 Hz cannot be applied at 100 Hz \\(compute them for that rate\\)"
  ARGS3 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}"
        --gains "${_data}/cart_pole_zero_gains.csv" --rate 100 --out @WORK@/closed.csv
  CHECKS3 "-DSTDERR_REGEX=warning: .*cart_pole_zero_gains.csv \\(for the scene .*\\) holds continuous gains K\\(t\\); at 100 Hz they are only sampled")
# A gain file of another scene with the same sizes (paper pendulum: 1 x 4 like the cart-pole) is
# refused, naming the first column whose name differs; --json prints one JSON object.
trellis_cli_files_test(gains.names_checked_and_json
  ARGS1 gains "${_paper}" --trajectory "${_paper_swing}" --R 0.01 --rate 100 --json --out @WORK@/paper.csv
  CHECKS1 -DSTDERR_EMPTY=ON
          "-DSTDOUT_REGEX=^\\{\"status\":\"ok\",\"ok\":true,\"message\":\"\",\"t\":null,\"index\":null,\"mode\":\"sampled\",\"sample_rate_hz\":100(\\.0)?,\"constrained\":true.*\"tangent_dimension\":2.*\"out\":.*paper.csv.*\"gramian_ok\":(true|false).*\\}\n$"
  ARGS2 simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}" --gains @WORK@/paper.csv
        --rate 100 --out @WORK@/closed.csv
  CHECKS2 -DEXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON
          "-DSTDERR_REGEX=paper.csv \\(for the scene .*cart_pole.json\\): column 2 is 'K\\[u\\|theta1\\]', but the scene's gain column there is 'K\\[push\\|x\\]'"
  ARGS3 simulate "${_paper}" --trajectory "${_paper_swing}" --gains @WORK@/paper.csv
        --perturb theta1=0.05 --rate 100 --json --out @WORK@/closed.csv
  # The report is built with the JSON library (issue 23): compact, the same keys.
  CHECKS3 "-DSTDOUT_REGEX=^\\{\"status\":\"ok\",\"ok\":true.*\"tracking_error_final\":[0-9].*\"sample_rate_hz\":100(\\.0)?,\"gains_sample_rate_hz\":100(\\.0)?.*\\}\n$")

# ---- balancing a pose from the command line (issue 27 part 2) ---------------------------------
# A fixed-base two-joint arm (URDF: a revolute shoulder and a light prismatic slide, joint inputs)
# held at its stored pose for 10 s at 100 Hz. --infinite-horizon: Qf = S_inf of the DARE, so every
# row is K_inf (measured 5.6e-15 relative); the reference used is written; the Gramian of the
# unstable hold does not print a smallest eigenvalue it could not resolve. simulate --hold runs the
# loop about the same pose: from a 0.1 rad shoulder error it settles and stays (final 2.1e-6,
# bound 1e-4). Step 3, the control that makes the test able to fail: the finite-horizon
# continuous gain with Qf = 100 ends in its terminal layer K(T) = R^-1 B^T Qf, which the 100 Hz
# loop cannot follow on the light slide: the settled loop blows up in the last 0.1 s (final error
# measured 5726, bound > 1). Step 4: the CARE gain (continuous, infinite horizon) sampled at
# 100 Hz also settles (final 2.1e-6).
set(_arm "${_data}/two_link_arm_scene.json")
trellis_cli_files_test(gains.hold_infinite_horizon_balances_at_100hz
  ARGS1 gains "${_arm}" --hold 10 --rate 100 --Q 10 --infinite-horizon
        --write-reference @WORK@/pose.csv --out @WORK@/gains.csv
  CHECKS1 -DSTDERR_EMPTY=ON -DFILE=@WORK@/pose.csv "-DFILE_HEADER=t,shoulder,slide,dshoulder,dslide,shoulder,slide"
          -DFILE_ROWS=101
          "-DSTDOUT_REGEX=1001 rows of K \\(2 x 4\\).*infinite horizon: Qf = S_inf of the DARE: ok.*feed-forward: consistent.*wrote .*pose.csv: the reference used \\(101 knots\\).*gramian on \\[0, 10\\]: max eigenvalue [0-9.e+]+; min eigenvalue not computed: it lies below 1e-10 x max"
          "-DNUMBERS=/ \\|K_inf\\| :LESS:1e-12"
  ARGS2 simulate "${_arm}" --hold 10 --rate 100 --gains @WORK@/gains.csv --perturb shoulder=0.1
        --out @WORK@/closed.csv
  CHECKS2 -DSTDERR_EMPTY=ON "-DSTDOUT_REGEX=feedback sampled at 100 Hz, feed-forward uff_k from the gain file"
          "-DNUMBERS=initial :GREATER:0.0999999&&final :LESS:1e-4"
  ARGS3 gains "${_arm}" --hold 10 --Q 10 --Qf 100 --out @WORK@/finite.csv
  CHECKS3 -DSTDERR_EMPTY=ON
  ARGS4 simulate "${_arm}" --hold 10 --rate 100 --gains @WORK@/finite.csv --perturb shoulder=0.1
        --out @WORK@/blown.csv
  CHECKS4 "-DNUMBERS=final :GREATER:1"
  ARGS5 gains "${_arm}" --hold 10 --Q 10 --infinite-horizon --out @WORK@/care.csv
  CHECKS5 -DSTDERR_EMPTY=ON "-DSTDOUT_REGEX=infinite horizon: Qf = S_inf of the CARE: ok"
  ARGS6 simulate "${_arm}" --hold 10 --rate 100 --gains @WORK@/care.csv --perturb shoulder=0.1
        --out @WORK@/closed_care.csv
  CHECKS6 "-DNUMBERS=final :LESS:1e-4")

# ---- help -------------------------------------------------------------------------------------
trellis_cli_test(gains.help ARGS gains --help
  CHECKS "-DSTDOUT_REGEX=usage: trellis gains SCENE.json --trajectory.*constraint manifold.*--rate HZ.*u_k = uff_k - K_k \\(x\\(t_k\\) - x_ref\\(t_k\\)\\).*K\\[<input>\\|<state>\\].*--Q W +state weight \\(default 1\\).*--R W.*--Qf W.*--dt DT +continuous gains written on a uniform grid.*only SAMPLES the continuous K\\(t\\): it does not\n *make gains for a controller running at 1/DT; use --rate for that"
         -DSTDERR_EMPTY=ON)
trellis_cli_test(gains.in_command_list ARGS --help CHECKS "-DSTDOUT_REGEX=  gains +TV-LQR")

# ---- errors: exit 2 (command line) or 1 (files, solve), one line on stderr, nothing on stdout --
set(_gains_args gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --out /dev/null)
set(_e2 -DEXPECT_EXIT=2 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON)
set(_e1 -DEXPECT_EXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON)
trellis_cli_test(gains.error.missing_trajectory
  ARGS gains "${_cart_pole}" --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=gains: missing --trajectory")
trellis_cli_test(gains.error.missing_out
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}"
  CHECKS ${_e2} "-DSTDERR_REGEX=gains: missing --out")
trellis_cli_test(gains.error.missing_scene
  ARGS gains --trajectory "${_cart_pole_upright}" --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=gains: missing the scene file")
trellis_cli_test(gains.error.unknown_option
  ARGS ${_gains_args} --bogus 1
  CHECKS ${_e2} "-DSTDERR_REGEX=gains: unknown option '--bogus'")
trellis_cli_test(gains.error.option_without_value
  ARGS ${_gains_args} --Q
  CHECKS ${_e2} "-DSTDERR_REGEX=option '--Q' needs a value")
trellis_cli_test(gains.error.weight_list_length
  ARGS ${_gains_args} --Q 1,2,3
  CHECKS ${_e2} "-DSTDERR_REGEX=--Q: '1,2,3' has 3 numbers; expected 1 .* or 4 \\(the diagonal: 2n = 4 states\\)")
trellis_cli_test(gains.error.input_weight_list_length
  ARGS ${_gains_args} --R 1,2
  CHECKS ${_e2} "-DSTDERR_REGEX=--R: '1,2' has 2 numbers; expected 1 .* or 1 \\(the diagonal: m = 1 inputs\\)")
trellis_cli_test(gains.error.weight_list_item
  ARGS ${_gains_args} --Q 1,,2,3
  CHECKS ${_e2} "-DSTDERR_REGEX=--Q: item 2 of '1,,2,3' \\(''\\) is not a finite number")
trellis_cli_test(gains.error.negative_Q
  ARGS ${_gains_args} --Q 1,-1,1,1
  CHECKS ${_e2} "-DSTDERR_REGEX=--Q: diagonal entry 2 = -1 must be >= 0")
trellis_cli_test(gains.error.zero_R
  ARGS ${_gains_args} --R 0
  CHECKS ${_e2} "-DSTDERR_REGEX=--R: diagonal entry 1 = 0 must be > 0")
trellis_cli_test(gains.error.bad_method
  ARGS ${_gains_args} --method euler
  CHECKS ${_e2} "-DSTDERR_REGEX=--method 'euler' is not one of bdf, adams, factored")
trellis_cli_test(gains.error.negative_dt
  ARGS ${_gains_args} --dt -0.1
  CHECKS ${_e2} "-DSTDERR_REGEX=--dt: -0.1 must be > 0")
trellis_cli_test(gains.error.weight_file_not_found
  ARGS ${_gains_args} --Qf "${_data}/no_such_weights.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=--Qf: weight file '.*no_such_weights.json' cannot be opened")
trellis_cli_test(gains.error.weight_file_malformed
  ARGS ${_gains_args} --Q "${_data}/weights_malformed.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=--Q: weight file '.*weights_malformed.json' is not valid JSON")
trellis_cli_test(gains.error.weight_file_not_square
  ARGS ${_gains_args} --Q "${_data}/weights_not_square.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=weights_not_square.json': row 1 has 3 entries; expected a list of 4 rows of 4 numbers")
trellis_cli_test(gains.error.weight_file_asymmetric
  ARGS ${_gains_args} --Q "${_data}/weights_asymmetric.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=weights_asymmetric.json': the matrix is not symmetric: entry \\(1, 2\\) = 1 but \\(2, 1\\) = 2")
trellis_cli_test(gains.error.weight_file_indefinite
  ARGS ${_gains_args} --Q "${_data}/weights_indefinite.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=weights_indefinite.json': the matrix is not positive semidefinite: smallest eigenvalue -1")
trellis_cli_test(gains.error.weight_file_wrong_size_for_R
  ARGS ${_gains_args} --R "${_data}/weights_cart_pole_Q.json"
  CHECKS ${_e1} "-DSTDERR_REGEX=--R: weight file .*expected a list of 1 rows of 1 numbers \\(m = 1 inputs\\), got 4 rows")
trellis_cli_test(gains.error.trajectory_not_found
  ARGS gains "${_cart_pole}" --trajectory "${_data}/no_such_trajectory.csv" --out /dev/null
  CHECKS ${_e1} "-DSTDERR_REGEX=no_such_trajectory.csv")
# A trajectory of another scene: the error names both files, nothing is written.
trellis_cli_files_test(gains.error.trajectory_columns_mismatch
  ARGS1 gains "${_cart_pole}" --trajectory "${_trajectories}/pendulum_swing.csv" --out @WORK@/gains.csv
  CHECKS1 -DEXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON -DABSENT=@WORK@/gains.csv
          "-DSTDERR_REGEX=pendulum_swing.csv does not match the scene .*cart_pole.json")
# Numerical failure of the solve (here: a step budget of 5) is exit 1 with the time and the cause,
# and no gains file.
trellis_cli_files_test(gains.error.solver_failure
  ARGS1 gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --max-steps 5 --out @WORK@/gains.csv
  CHECKS1 -DEXIT=1 -DSTDOUT_EMPTY=ON -DSTDERR_ONE_LINE=ON -DABSENT=@WORK@/gains.csv
          "-DSTDERR_REGEX=gains: riccati_failure at t = .*: the Riccati solve failed: integrator_failure at t = .*t = 3.*maxSteps = 5")
trellis_cli_test(gains.error.rate_and_dt
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --rate 50 --dt 0.1 --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=gains: --rate and --dt exclude each other")
trellis_cli_test(gains.error.rate_not_positive
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --rate -5 --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--rate: -5 must be > 0")

# --infinite-horizon needs a held pose and excludes --Qf; simulate --hold excludes --trajectory.
trellis_cli_test(gains.error.infinite_horizon_needs_hold
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --infinite-horizon --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--infinite-horizon applies to a held pose only \\(--hold T\\)")
trellis_cli_test(gains.error.infinite_horizon_and_qf
  ARGS gains "${_cart_pole}" --hold 1 --infinite-horizon --Qf 5 --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--infinite-horizon and --Qf exclude each other")
trellis_cli_test(simulate.error.hold_and_trajectory
  ARGS simulate "${_cart_pole}" --hold 1 --trajectory "${_cart_pole_upright}" --gains g.csv --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--hold and --trajectory exclude each other")
trellis_cli_test(gains.error.feedforward_needs_rate
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --feedforward average --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--feedforward applies to sampled gains only \\(--rate\\)")
trellis_cli_test(gains.error.feedforward_unknown
  ARGS gains "${_cart_pole}" --trajectory "${_cart_pole_upright}" --rate 10 --feedforward best --out /dev/null
  CHECKS ${_e2} "-DSTDERR_REGEX=--feedforward 'best' is not one of reference, average, consistent")

# A sampled gain file written before issue 27 (columns K_<input>_<state>, no uff columns) is still
# read and applied; the summary says the feed-forward is then u_ref(t_k).
trellis_cli_test(simulate.older_sampled_gain_file
  ARGS simulate "${_cart_pole}" --trajectory "${_cart_pole_upright}"
       --gains "${_data}/cart_pole_gains_older_sampled_10hz.csv" --rate 10 --perturb theta=0.05 --out /dev/null
  CHECKS -DSTDERR_EMPTY=ON
         "-DSTDOUT_REGEX=feedback sampled at 10 Hz, feed-forward u_ref\\(t_k\\) \\(the gain file has none\\)")
