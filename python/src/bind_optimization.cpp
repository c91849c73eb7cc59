// python/src/bind_optimization.cpp — trellis::optimization: optimal control problems (from files or
// built in Python), optimize_trajectory (Ipopt, GIL released) and its result.
#include "common.hpp"
#include "options.hpp"

#include <pybind11/functional.h>

#include <atomic>
#include <memory>
#include <mutex>

#include "trellis/optimization/optimizer.hpp"
#include "trellis/optimization/problem.hpp"

namespace trellis::python {

namespace {

using Problem = OptimalControlProblem;

}  // namespace

void bindOptimization(py::module_& m) {
  py::enum_<CollocationMethod>(m, "CollocationMethod")
      .value("HERMITE_SIMPSON", CollocationMethod::kHermiteSimpson)
      .value("TRAPEZOIDAL", CollocationMethod::kTrapezoidal)
      .value("RADAU", CollocationMethod::kRadau);
  py::enum_<DerivativeMode>(m, "DerivativeMode")
      .value("EXACT", DerivativeMode::kExact)
      .value("FINITE_DIFFERENCE", DerivativeMode::kFiniteDifference);
  py::enum_<DynamicsForm>(m, "DynamicsForm",
                          "How the transcription imposes the dynamics: EXPLICIT (f(x, u) from the "
                          "forward dynamics) or IMPLICIT (q'' and lambda as variables, the equations of "
                          "motion M q'' + b - A^T lambda = 0 and A q'' + Adot q' = 0 as rows; L-BFGS Hessian).")
      .value("EXPLICIT", DynamicsForm::kExplicit)
      .value("IMPLICIT", DynamicsForm::kImplicit);
  py::enum_<HessianMode>(m, "HessianMode",
                         "The Lagrangian Hessian Ipopt uses: EXACT (the transcription's exact second "
                         "derivatives) or LBFGS (limited-memory quasi-Newton).")
      .value("EXACT", HessianMode::kExact)
      .value("LBFGS", HessianMode::kLimitedMemory);
  py::enum_<MumpsOrdering>(m, "MumpsOrdering",
                           "MUMPS's fill-reducing ordering of Ipopt's KKT matrix (mumps_pivot_order): "
                           "AUTO (MUMPS chooses), AMD, AMF, SCOTCH, PORD, METIS, QAMD.")
      .value("AUTO", MumpsOrdering::kAuto)
      .value("AMD", MumpsOrdering::kAmd)
      .value("AMF", MumpsOrdering::kAmf)
      .value("SCOTCH", MumpsOrdering::kScotch)
      .value("PORD", MumpsOrdering::kPord)
      .value("METIS", MumpsOrdering::kMetis)
      .value("QAMD", MumpsOrdering::kQamd);
  py::enum_<OptimizationCode>(m, "OptimizationCode",
                              "The code of an OptimizationResult's status (SOLVED and "
                              "SOLVED_ACCEPTABLE are success).")
      .value("SOLVED", OptimizationCode::kSolved)
      .value("SOLVED_ACCEPTABLE", OptimizationCode::kSolvedAcceptable)
      .value("INCONSISTENT", OptimizationCode::kInconsistent)
      .value("INFEASIBLE", OptimizationCode::kInfeasible)
      .value("ITERATION_LIMIT", OptimizationCode::kIterationLimit)
      .value("STOPPED", OptimizationCode::kStopped)
      .value("FAILED", OptimizationCode::kFailed);

  py::class_<Problem> problem(m, "OptimalControlProblem",
      "minimize int_0^T u^T R u + (x - x_goal)^T Q (x - x_goal) dt + (x(T) - x_goal)^T Qf (x(T) - "
      "x_goal) + w_T T subject to xdot = f(x, u), the constraints, bounds and boundary states; "
      "x = [q; dq] (nx = 2n), u (nu). Made by load_problem / parse_problem or "
      "OptimalControlProblem(model) (defaults: zero boundary states, all fixed, no bounds, R = I, "
      "Q = Qf = 0). Vector and matrix fields are copied in and out.");
  problem
      .def(py::init([](ModelPtr model) { return Problem(std::const_pointer_cast<const Model>(model)); }),
           py::arg("model").none(false))
      .def_property_readonly("model",
                             [](const Problem& p) { return std::const_pointer_cast<Model>(p.model); })
      .def_readwrite("method", &Problem::method)
      .def_readwrite("dynamics", &Problem::dynamics, "DynamicsForm (file key \"dynamics\")")
      .def_readwrite("knots", &Problem::knots, "N >= 2 knots t_k = k T / (N - 1)")
      .def_readwrite("horizon", &Problem::horizon, "T (the initial guess when free)")
      .def_readwrite("min_horizon", &Problem::minHorizon)
      .def_readwrite("max_horizon", &Problem::maxHorizon)
      .def_property_readonly("free_horizon", &Problem::freeHorizon)
      .def("set_fixed_horizon", &Problem::setFixedHorizon, py::arg("T"))
      .def_readwrite("initial_fixed", &Problem::initialFixed, "nx flags (list of bool)")
      .def_readwrite("final_fixed", &Problem::finalFixed, "nx flags (list of bool)")
      .def_readwrite("initial_acceleration_fixed", &Problem::initialAccelerationFixed,
                     "nq flags (list of bool) or []: qdd_i = 0 at the first knot (implicit form only)")
      .def_readwrite("final_acceleration_fixed", &Problem::finalAccelerationFixed,
                     "nq flags (list of bool) or []: qdd_i = 0 at the last knot (implicit form only)")
      .def_readwrite("time_weight", &Problem::timeWeight)
      .def_readwrite("initial_guess", &Problem::initialGuess, "a Trajectory or None")
      .def_readwrite("hessian", &Problem::hessian,
                     "HessianMode unless OptimizerOptions.hessian overrides it (file key \"hessian\")")
      .def_property_readonly("nq", &Problem::nq)
      .def_property_readonly("nx", &Problem::nx)
      .def_property_readonly("nu", &Problem::nu)
      .def_property_readonly("state_names", &Problem::stateNames)
      .def("validate", &Problem::validate, "Raises ProblemError naming the first bad field.");
  realArrayProperty(problem, "initial_state", &Problem::initialState, "(nx,)");
  realArrayProperty(problem, "final_state", &Problem::finalState, "(nx,)");
  realArrayProperty(problem, "state_lower", &Problem::stateLower, "(nx,), -inf for none");
  realArrayProperty(problem, "state_upper", &Problem::stateUpper, "(nx,), +inf for none");
  realArrayProperty(problem, "input_lower", &Problem::inputLower, "(nu,)");
  realArrayProperty(problem, "input_upper", &Problem::inputUpper, "(nu,)");
  realArrayProperty(problem, "goal_state", &Problem::goalState, "(nx,)");
  realArrayProperty(problem, "force_lower", &Problem::forceLower,
                 "(nc,) bounds on the constraint forces at every collocation point, -inf for none");
  realArrayProperty(problem, "force_upper", &Problem::forceUpper, "(nc,), +inf for none");
  realArrayProperty(problem, "R", &Problem::R, "(nu, nu) symmetric PSD");
  realArrayProperty(problem, "Q", &Problem::Q, "(nx, nx) symmetric PSD");
  realArrayProperty(problem, "Qf", &Problem::Qf, "(nx, nx) symmetric PSD");
  realArrayProperty(problem, "acceleration_weights", &Problem::accelerationWeights,
                    "(nq,) or empty: adds the integral of qdd^T diag(w) qdd (implicit dynamics form only)");

  m.def("load_problem", &loadProblem, py::arg("path"),
        "Reads a problem file (JSON, optimization/README.md); paths inside are relative to it. "
        "Raises ProblemError (or ModelError for its scene).");
  m.def("parse_problem", &parseProblem, py::arg("text"), py::arg("source") = "<problem>",
        py::arg("base_dir") = ".", "Parses problem-file JSON text; base_dir resolves its paths.");

  py::class_<IterationInfo>(m, "IterationInfo", "One Ipopt iteration (passed to on_iteration).")
      .def_readonly("iteration", &IterationInfo::iteration)
      .def_readonly("cost", &IterationInfo::cost)
      .def_readonly("constraint_violation", &IterationInfo::constraintViolation)
      .def_readonly("dual_infeasibility", &IterationInfo::dualInfeasibility)
      .def_readonly("step_size", &IterationInfo::stepSize)
      .def_readonly("restoration", &IterationInfo::restoration);

  py::class_<OptimizerOptions>(m, "OptimizerOptions",
      "Ipopt options (keywords): print_level, max_iterations, tolerance, constraint_tolerance, "
      "max_cpu_time, limited_memory_size, ordering (MumpsOrdering), threads (the implicit form's "
      "Hessian blocks; the same iterates on any count), derivatives (DerivativeMode), hessian (HessianMode or None: "
      "the problem's), warm_start (refinement rounds start from the carried primal and multipliers), "
      "warm_start_barrier (Ipopt's mu_init then), consistency_tolerance, max_refinements, max_knots, "
      "max_split, refinement_band (neighbours of a cut interval halved too), unresolved_defect (a "
      "worst defect above it halves every interval), refinement_grading (0: off; else neighbouring new "
      "widths within this factor), on_iteration (a callable taking an IterationInfo and returning False to stop; an "
      "exception in it stops the solve).")
      .def(py::init(&makeFromKwargs<OptimizerOptions>))
      .def_readwrite("print_level", &OptimizerOptions::printLevel)
      .def_readwrite("max_iterations", &OptimizerOptions::maxIterations)
      .def_readwrite("tolerance", &OptimizerOptions::tolerance)
      .def_readwrite("constraint_tolerance", &OptimizerOptions::constraintTolerance)
      .def_readwrite("max_cpu_time", &OptimizerOptions::maxCpuTime)
      .def_readwrite("limited_memory_size", &OptimizerOptions::limitedMemorySize)
      .def_readwrite("ordering", &OptimizerOptions::ordering)
      .def_readwrite("threads", &OptimizerOptions::threads)
      .def_readwrite("derivatives", &OptimizerOptions::derivatives)
      .def_readwrite("hessian", &OptimizerOptions::hessian)
      .def_readwrite("warm_start", &OptimizerOptions::warmStart)
      .def_readwrite("warm_start_barrier", &OptimizerOptions::warmStartBarrier)
      .def_readwrite("consistency_tolerance", &OptimizerOptions::consistencyTolerance)
      .def_readwrite("max_refinements", &OptimizerOptions::maxRefinements)
      .def_readwrite("max_knots", &OptimizerOptions::maxKnots)
      .def_readwrite("max_split", &OptimizerOptions::maxSplit)
      .def_readwrite("refinement_band", &OptimizerOptions::refinementBand)
      .def_readwrite("unresolved_defect", &OptimizerOptions::unresolvedDefect)
      .def_readwrite("refinement_grading", &OptimizerOptions::refinementGrading)
      .def_readwrite("on_iteration", &OptimizerOptions::onIteration)
      .def("validate", &OptimizerOptions::validate);

  py::class_<OptimizationResult>(m, "OptimizationResult",
      "status (OptimizationCode), ok, message, t, index (the status: t and index name the worst "
      "interval when inconsistent), ipopt_status, iterations (all rounds), rounds, hessian, cost, "
      "constraint_violation, bound_violation, max_slack, solve_time, solve_cpu_time, evaluation_time, hessian_time, check_time, horizon, "
      "evaluation counts, the trajectory (knots), Hermite-Simpson midpoints, the NLP variables and "
      "multipliers; describe() and json() are the library's reports.")
      .def_property_readonly("status", [](const OptimizationResult& r) { return r.status.code; })
      .def_property_readonly("ok", &OptimizationResult::ok)
      .def_property_readonly("message", [](const OptimizationResult& r) { return r.status.message; })
      .def_property_readonly("t", [](const OptimizationResult& r) { return r.status.t; })
      .def_property_readonly("index", [](const OptimizationResult& r) { return r.status.index; })
      .def("describe", &OptimizationResult::describe)
      .def("json", &OptimizationResult::json)
      .def_readonly("ipopt_status", &OptimizationResult::ipoptStatus)
      .def_readonly("hessian", &OptimizationResult::hessian)
      .def_readonly("hessian_note", &OptimizationResult::hessianNote)
      .def_property_readonly("rounds",
                             [](const OptimizationResult& r) {
                               py::list rounds;
                               for (const RefinementRound& x : r.rounds) {
                                 py::dict d;
                                 d["knots"] = x.knots;
                                 d["iterations"] = x.iterations;
                                 d["ipopt_status"] = x.ipoptStatus;
                                 d["defect"] = x.maxDefect;
                                 d["slack_defect"] = x.maxSlackDefect;
                                 d["hessian"] = x.hessian;
                                 d["solve_time"] = x.solveTime;
                                 rounds.append(d);
                               }
                               return rounds;
                             },
                             "one dict per solve (knots, iterations, ipopt_status, defect, "
                             "slack_defect, hessian, solve_time)")
      .def_readonly("iterations", &OptimizationResult::iterations)
      .def_readonly("cost", &OptimizationResult::cost)
      .def_readonly("constraint_violation", &OptimizationResult::constraintViolation)
      .def_readonly("bound_violation", &OptimizationResult::boundViolation)
      .def_readonly("max_slack", &OptimizationResult::maxSlack)
      .def_readonly("solve_time", &OptimizationResult::solveTime)
      .def_readonly("solve_cpu_time", &OptimizationResult::solveCpuTime)
      .def_readonly("evaluation_time", &OptimizationResult::evaluationTime)
      .def_readonly("hessian_time", &OptimizationResult::hessianTime)
      .def_readonly("check_time", &OptimizationResult::checkTime)
      .def_readonly("horizon", &OptimizationResult::horizon)
      .def_readonly("dynamics_evaluations", &OptimizationResult::dynamicsEvaluations)
      .def_readonly("linearization_evaluations", &OptimizationResult::linearizationEvaluations)
      .def_readonly("second_order_evaluations", &OptimizationResult::secondOrderEvaluations)
      .def_readonly("trajectory", &OptimizationResult::trajectory)
      .def_property_readonly("midpoint_states",
                             [](const OptimizationResult& r) { return toArray(Eigen::MatrixXd(r.midpointStates.transpose())); },
                             "(N - 1, nx), time first")
      .def_property_readonly("midpoint_inputs",
                             [](const OptimizationResult& r) { return toArray(Eigen::MatrixXd(r.midpointInputs.transpose())); },
                             "(N - 1, nu), time first")
      .def_property_readonly("variables",
                             [](const OptimizationResult& r) { return toArray(r.variables); })
      .def_property_readonly("constraint_multipliers",
                             [](const OptimizationResult& r) { return toArray(r.constraintMultipliers); })
      .def("__repr__", [](const OptimizationResult& r) { return "<OptimizationResult " + r.describe() + ">"; });

  m.def("optimize_trajectory",
        [](const Problem& problem, const std::optional<OptimizerOptions>& options) {
          OptimizerOptions solver = options.value_or(OptimizerOptions{});
          // Ctrl-C inside on_iteration is a KeyboardInterrupt in the callback; the optimizer would
          // turn any exception into a stopped solve. It stops the solve here and is raised again
          // once the solve has returned, so the script stops as Ctrl-C means.
          auto interrupted = std::make_shared<std::atomic<bool>>(false);
          if (solver.onIteration) {
            solver.onIteration = [inner = std::move(solver.onIteration), interrupted](const IterationInfo& info) {
              try {
                return inner(info);
              } catch (py::error_already_set& e) {
                py::gil_scoped_acquire gil;
                if (e.matches(PyExc_KeyboardInterrupt)) {
                  interrupted->store(true);
                  return false;
                }
                throw;
              }
            };
          }
          OptimizationResult result;
          {
            py::gil_scoped_release release;
            // Ipopt with Debian's sequential MUMPS is not reentrant (two concurrent solves crash in
            // the linear solver): solves are serialized here, while other Python threads run.
            static std::mutex ipoptMutex;
            const std::lock_guard<std::mutex> lock(ipoptMutex);
            result = optimizeTrajectory(problem, solver);
          }
          if (interrupted->load()) {
            PyErr_SetNone(PyExc_KeyboardInterrupt);
            throw py::error_already_set();
          }
          return result;
        },
        py::arg("problem"), py::kw_only(), py::arg("options") = py::none(),
        "Transcribes (direct collocation) and solves with Ipopt, without the GIL (other Python threads "
        "run meanwhile; concurrent solves are serialized: Ipopt/MUMPS is not reentrant). Bad problems or "
        "options raise ProblemError / ValueError; a numerical failure is the result's status.");
}

}  // namespace trellis::python
