// simulation_report.cpp — the simulator's names, option checks and JSON summary (no numerics).
#include "trellis/analysis/simulation.hpp"

#include "trellis/analysis/detail/option_check.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

IntegrationMethod parseIntegrationMethod(const std::string& text) {
  return parseEnum<IntegrationMethod>(text, "integration method");
}

std::string SimulationResult::describe() const {
  const Eigen::VectorXd& e = trackingError;
  std::string line = status.describe() + " (" + std::to_string(trajectory.size()) + " rows";
  if (e.size() > 0) {
    line += ", tracking error final " + formatStatusNumber(e(e.size() - 1)) + ", max " +
            formatStatusNumber(e.maxCoeff());
  }
  line += ", max drift " + formatStatusNumber(maxConstraintDrift) + ", " + std::to_string(steps) + " steps)";
  return line;
}

std::string SimulationResult::json() const {
  const SimulationResult& r = *this;
  using detail::ReportJson;
  using detail::toJson;
  const Trajectory& tr = r.trajectory;
  const bool have = tr.size() > 0;
  const Eigen::VectorXd& e = r.trackingError;
  Eigen::Index worst = 0;
  if (e.size() > 0) e.maxCoeff(&worst);
  const ReportJson null(nullptr);
  ReportJson j = detail::statusJson(r.status);
  j["rows"] = tr.size();
  j["t0"] = have ? toJson(tr.startTime()) : null;
  j["t1"] = have ? toJson(tr.endTime()) : null;
  j["tracking_error_initial"] = e.size() > 0 ? toJson(e(0)) : null;
  j["tracking_error_final"] = e.size() > 0 ? toJson(e(e.size() - 1)) : null;
  j["tracking_error_max"] = e.size() > 0 ? toJson(e(worst)) : null;
  j["tracking_error_max_time"] = e.size() > 0 && have ? toJson(tr.times()(worst)) : null;
  j["max_constraint_drift"] = toJson(r.maxConstraintDrift);
  j["saturated_samples"] = r.saturatedSamples;
  j["control_samples"] = r.controlSamples;
  j["saturated_fraction"] = toJson(r.saturatedFraction);
  j["steps"] = r.steps;
  j["rhs_evaluations"] = r.rhsEvaluations;
  j["difference_quotient_rhs_evaluations"] = r.linearRhsEvaluations;
  j["jacobian_evaluations"] = r.jacobianEvaluations;
  j["restarts"] = r.restarts;
  j["projections"] = r.projections;
  j["checks"] = r.checks;
  return j.dump();
}

void SimulationOptions::validate() const {
  auto bad = [](const std::string& field, double v, const char* rule) {
    detail::badOption("SimulationOptions", field, v, rule);
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps), "> 0");
  if (!(newtonTolerance >= 0.0 && newtonTolerance < 1.0))
    bad("newtonTolerance", newtonTolerance, "0 (RADAU5's default) or in (0, 1)");
  if (!(sampleRate >= 0.0) || !std::isfinite(sampleRate))
    bad("sampleRate", sampleRate, ">= 0 and finite");
  if (!(outputStep >= 0.0) || !std::isfinite(outputStep))
    bad("outputStep", outputStep, ">= 0 and finite");
  if (!(maxStep >= 0.0) || !std::isfinite(maxStep)) bad("maxStep", maxStep, ">= 0 and finite");
  if (!(driftTolerance >= 0.0) || !std::isfinite(driftTolerance))
    bad("driftTolerance", driftTolerance, ">= 0 and finite");
  if (projectionIterations < 1) {
    bad("projectionIterations", projectionIterations, ">= 1");
  }
  for (std::size_t k = 0; k < breakpoints.size(); ++k) {
    if (!std::isfinite(breakpoints[k]))
      bad("breakpoints[" + std::to_string(k) + "]", breakpoints[k], "finite");
  }
  if (inputLower.size() != 0 && inputUpper.size() != 0 && inputLower.size() != inputUpper.size()) {
    std::ostringstream m;
    m << "SimulationOptions.inputLower has size " << inputLower.size()
      << " but SimulationOptions.inputUpper has size " << inputUpper.size();
    throw std::invalid_argument(m.str());
  }
  for (Eigen::Index i = 0; i < inputLower.size(); ++i) {
    if (std::isnan(inputLower(i)) || inputLower(i) == std::numeric_limits<double>::infinity()) {
      bad("inputLower[" + std::to_string(i) + "]", inputLower(i), "a number < +inf");
    }
  }
  for (Eigen::Index i = 0; i < inputUpper.size(); ++i) {
    if (std::isnan(inputUpper(i)) || inputUpper(i) == -std::numeric_limits<double>::infinity()) {
      bad("inputUpper[" + std::to_string(i) + "]", inputUpper(i), "a number > -inf");
    }
    if (i < inputLower.size() && !(inputLower(i) <= inputUpper(i))) {
      std::ostringstream m;
      m << "SimulationOptions.inputLower[" << i << "] = " << inputLower(i)
        << " is greater than SimulationOptions.inputUpper[" << i << "] = " << inputUpper(i);
      throw std::invalid_argument(m.str());
    }
  }
}

}  // namespace trellis
