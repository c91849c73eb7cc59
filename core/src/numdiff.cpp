// numdiff.cpp — finite differences of the dynamics (numdiff.hpp: schemes, steps, error model).
#include "trellis/core/numdiff.hpp"
#include "trellis/core/detail/report_json.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

double defaultRelativeStep(DifferenceScheme scheme) {
  const double eps = std::numeric_limits<double>::epsilon();
  switch (scheme) {
    case DifferenceScheme::kForward: return std::sqrt(eps);
    case DifferenceScheme::kCentral: return std::cbrt(eps);
    case DifferenceScheme::kCentralFourthOrder: return std::pow(eps, 0.2);
  }
  return std::cbrt(eps);
}

double NumDiffOptions::step(double z) const {
  const double rel = relativeStep > 0.0 ? relativeStep : defaultRelativeStep(scheme);
  return rel * std::max(1.0, std::abs(z));
}

namespace {

/// One column of any scheme: `eval(offset, out)` evaluates f at z_j + offset. `base` is f(z)
/// (forward only), `plus`/`minus` scratch. Returns false when an evaluation failed.
template <class Eval, class Column>
bool differenceColumn(const NumDiffOptions& o, double zj, const Eigen::VectorXd& base,
                      Eigen::VectorXd& plus, Eigen::VectorXd& minus, Eval&& eval, Column&& column) {
  const double h = o.step(zj);
  switch (o.scheme) {
    case DifferenceScheme::kForward: {
      const double taken = (zj + h) - zj;
      if (!eval(h, plus)) return false;
      column() = (plus - base) / taken;
      return true;
    }
    case DifferenceScheme::kCentral: {
      const double taken = (zj + h) - (zj - h);
      if (!eval(h, plus) || !eval(-h, minus)) return false;
      column() = (plus - minus) / taken;
      return true;
    }
    case DifferenceScheme::kCentralFourthOrder: {
      if (!eval(h, plus) || !eval(-h, minus)) return false;
      column() = 8.0 * (plus - minus);
      if (!eval(2.0 * h, plus) || !eval(-2.0 * h, minus)) return false;
      column() -= plus - minus;
      column() /= 12.0 * h;
      return true;
    }
  }
  return false;
}

}  // namespace

NumDiffWorkspace::NumDiffWorkspace(const Model& model)
    : q(model.nq()), dq(model.nq()), u(model.nu()), qddBase(model.nq()), qddPlus(model.nq()),
      qddMinus(model.nq()) {}

DynamicsStatus differenceDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                                  const Eigen::VectorXd& dq, const Eigen::VectorXd& u,
                                  const NumDiffOptions& options, NumDiffWorkspace& ws,
                                  Eigen::MatrixXd& J) {
  const int n = model.nq(), m = model.nu();
  if (J.rows() != n || J.cols() != 2 * n + m) J.resize(n, 2 * n + m);
  ws.q = q;
  ws.dq = dq;
  ws.u = u;
  DynamicsStatus failure;
  if (options.scheme == DifferenceScheme::kForward) {
    const DynamicsStatus s = computeDynamics(model, data, ws.q, ws.dq, ws.u);
    if (!s.ok()) return s;
    ws.qddBase = data.qdd;
  }
  for (int j = 0; j < 2 * n + m; ++j) {
    double& zj = j < n ? ws.q(j) : (j < 2 * n ? ws.dq(j - n) : ws.u(j - 2 * n));
    const double z0 = zj;
    auto eval = [&](double offset, Eigen::VectorXd& out) {
      zj = z0 + offset;
      const DynamicsStatus s = computeDynamics(model, data, ws.q, ws.dq, ws.u);
      zj = z0;
      if (!s.ok()) {
        failure = s;
        failure.message = "column " + std::to_string(j) + " perturbed by " + std::to_string(offset) +
                          ": " + s.message;
        return false;
      }
      out = data.qdd;
      return true;
    };
    if (!differenceColumn(options, z0, ws.qddBase, ws.qddPlus, ws.qddMinus, eval,
                          [&]() { return J.col(j); })) {
      return failure;
    }
  }
  return DynamicsStatus{};
}

Eigen::MatrixXd differenceJacobian(const DifferenceFunction& f, const Eigen::VectorXd& x,
                                   const NumDiffOptions& options) {
  Eigen::VectorXd base;
  f(x, base);
  Eigen::MatrixXd J(base.size(), x.size());
  Eigen::VectorXd xp = x, plus, minus;
  for (Eigen::Index j = 0; j < x.size(); ++j) {
    auto eval = [&](double offset, Eigen::VectorXd& out) {
      xp(j) = x(j) + offset;
      f(xp, out);
      xp(j) = x(j);
      if (out.size() != base.size()) {
        throw std::logic_error("differenceJacobian: the function changed its output size");
      }
      return true;
    };
    differenceColumn(options, x(j), base, plus, minus, eval, [&]() { return J.col(j); });
  }
  return J;
}

LinearizationCheck checkLinearization(const Model& model, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& dq, const Eigen::VectorXd& u,
                                      const NumDiffOptions& options) {
  const int n = model.nq(), m = model.nu();
  LinearizationCheck out;
  Data data(model);
  const DynamicsStatus exact = computeLinearization(model, data, q, dq, u);
  if (!exact.ok()) {
    out.status.set(LinearizationCheckCode::kExactFailed, "computeLinearization: " + exact.describe());
    return out;
  }
  out.exactJ.resize(n, 2 * n + m);
  out.exactJ << data.A.bottomRows(n), data.B.bottomRows(n);
  NumDiffWorkspace ws(model);
  const DynamicsStatus fd = differenceDynamics(model, data, q, dq, u, options, ws, out.differenceJ);
  if (!fd.ok()) {
    out.status.set(LinearizationCheckCode::kDifferenceFailed, "finite differences: " + fd.describe());
    return out;
  }
  for (int j = 0; j < 2 * n + m; ++j) {
    const double scale = std::max(1.0, out.differenceJ.col(j).cwiseAbs().maxCoeff());
    for (int i = 0; i < n; ++i) {
      const double e = std::abs(out.exactJ(i, j) - out.differenceJ(i, j)) / scale;
      if (e > out.maxError || out.row < 0) {
        out.maxError = e;
        out.row = i;
        out.column = j;
      }
    }
  }
  const auto& names = model.configNames();
  out.rowName = "dd" + names[out.row];
  out.columnName = out.column < n ? names[out.column]
                 : out.column < 2 * n ? "d" + names[out.column - n]
                                      : model.inputNames()[out.column - 2 * n];
  out.exact = out.exactJ(out.row, out.column);
  out.difference = out.differenceJ(out.row, out.column);
  return out;
}

std::string LinearizationCheck::describe() const {
  if (!ok()) return status.describe();
  std::ostringstream s;
  s.precision(6);
  s << "ok: worst entry d(" << rowName << ")/d(" << columnName << "): exact " << exact
    << ", finite difference " << difference << ", column-relative error " << maxError;
  return s.str();
}

std::string LinearizationCheck::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["max_error"] = detail::toJson(maxError);
  j["row"] = row;
  j["column"] = column;
  j["row_name"] = rowName;
  j["column_name"] = columnName;
  j["exact"] = detail::toJson(exact);
  j["difference"] = detail::toJson(difference);
  return j.dump();
}

}  // namespace trellis
