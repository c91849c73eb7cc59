// riccati_options.cpp — names, option validation and the weight-matrix check of the Riccati
// solver.
#include "trellis/control/riccati.hpp"

#include "trellis/analysis/detail/option_check.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace trellis {

RiccatiMethod parseRiccatiMethod(const std::string& text) {
  return parseEnum<RiccatiMethod>(text, "Riccati method");
}

RiccatiLinearSolver parseRiccatiLinearSolver(const std::string& text) {
  return parseEnum<RiccatiLinearSolver>(text, "Riccati linear solver");
}

void RiccatiOptions::validate() const {
  auto bad = [](const char* field, double v, const char* rule) {
    detail::badOption("RiccatiOptions", field, v, rule);
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps), "> 0");
  if (!(maxNorm > 0.0)) bad("maxNorm", maxNorm, "> 0");
  if (!(initialStep >= 0.0) || !std::isfinite(initialStep)) bad("initialStep", initialStep, ">= 0");
  if (!(maxStep >= 0.0) || !std::isfinite(maxStep)) bad("maxStep", maxStep, ">= 0");
  if (!(factoredSwitchCondition >= 0.0) || std::isnan(factoredSwitchCondition)) {
    bad("factoredSwitchCondition", factoredSwitchCondition, ">= 0");
  }
  if (!(factoredQfShift >= 0.0) || !std::isfinite(factoredQfShift)) {
    bad("factoredQfShift", factoredQfShift, ">= 0 and finite");
  }
  if (!(psdSlack >= 0.0) || std::isnan(psdSlack)) bad("psdSlack", psdSlack, ">= 0");
  const int orderLimit = method == RiccatiMethod::kAdams ? 12 : 5;
  if (maxOrder < 0 || maxOrder > orderLimit) {
    bad("maxOrder", maxOrder, method == RiccatiMethod::kAdams ? "0 (default) or 1..12 for Adams" : "0 (default) or 1..5 for BDF");
  }
  if (method == RiccatiMethod::kFactored && linearSolver == RiccatiLinearSolver::kLyapunov) {
    throw std::invalid_argument(
        "RiccatiOptions.linearSolver = lyapunov needs the plain form (method bdf): the factored "
        "form's Newton matrix is not a Lyapunov operator (use krylov, dense or auto)");
  }
}

void checkWeightMatrix(const Eigen::MatrixXd& W, const char* name, Eigen::Index size,
                       bool definite) {
  std::ostringstream m;
  if (W.rows() != size || W.cols() != size) {
    m << name << " must be " << size << "x" << size << ", got " << W.rows() << "x" << W.cols();
    throw std::invalid_argument(m.str());
  }
  if (size == 0) return;
  if (!W.allFinite()) {
    m << name << " has a non-finite entry";
    throw std::invalid_argument(m.str());
  }
  const double scale = std::max(1.0, W.cwiseAbs().maxCoeff());
  const double asym = (W - W.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-10 * scale) {
    m << name << " is not symmetric: max |W - W^T| = " << asym;
    throw std::invalid_argument(m.str());
  }
  const Eigen::MatrixXd Ws = 0.5 * (W + W.transpose());
  const double lmin = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ws, Eigen::EigenvaluesOnly)
                          .eigenvalues()(0);
  if (definite && !(lmin > 0.0)) {
    m << name << " is not positive definite: smallest eigenvalue " << lmin << " (must be > 0)";
    throw std::invalid_argument(m.str());
  }
  if (!definite && lmin < -1e-12 * scale) {
    m << name << " is not positive semidefinite: smallest eigenvalue " << lmin
      << " (must be >= 0)";
    throw std::invalid_argument(m.str());
  }
}

}  // namespace trellis
