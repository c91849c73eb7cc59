// python/src/control_common.cpp — see control_common.hpp.
#include "control_common.hpp"

#include <string>

namespace trellis::python {

namespace {

/// A weight given as a number (w·I), a 1-D array of n entries (its diagonal) or an n×n matrix.
Eigen::MatrixXd weightMatrix(const py::object& w, Eigen::Index n, const char* name) {
  if (py::isinstance<py::float_>(w) || py::isinstance<py::int_>(w)) {
    return w.cast<double>() * Eigen::MatrixXd::Identity(n, n);
  }
  refuseComplex(w, name, "a real number, diagonal or matrix");
  const auto a = py::array_t<double, py::array::forcecast>::ensure(w);
  if (!a) throw std::invalid_argument(std::string(name) + ": expected a number or a float array");
  if (a.ndim() == 0) return a.data()[0] * Eigen::MatrixXd::Identity(n, n);  // NumPy scalar
  if (a.ndim() == 1) {
    checkSize(a.shape(0), n, name, "diagonal entries");
    Eigen::VectorXd d(n);
    for (Eigen::Index i = 0; i < n; ++i) d(i) = a.at(i);
    return d.asDiagonal();
  }
  if (a.ndim() == 2 && a.shape(0) == n && a.shape(1) == n) {
    Eigen::MatrixXd W(n, n);
    for (Eigen::Index i = 0; i < n; ++i) {
      for (Eigen::Index j = 0; j < n; ++j) W(i, j) = a.at(i, j);
    }
    return W;
  }
  throw std::invalid_argument(std::string(name) + ": expected a number, " + std::to_string(n) +
                              " diagonal entries or a " + std::to_string(n) + "x" +
                              std::to_string(n) + " matrix");
}

}  // namespace

LqrWeights makeWeights(const py::object& Q, const py::object& R, const py::object& Qf,
                       Eigen::Index nx, Eigen::Index nu) {
  LqrWeights w;
  w.Q = weightMatrix(Q, nx, "Q");
  w.R = weightMatrix(R, nu, "R");
  w.Qf = Qf.is_none() ? w.Q : weightMatrix(Qf, nx, "Qf");
  return w;
}

std::vector<Eigen::MatrixXd> gainsFromArray(const py::object& gains) {
  refuseComplex(gains, "gains", "a real (float64) array (N, nu, nx)");
  const auto g = py::array_t<double, py::array::forcecast>::ensure(gains);
  if (!g || g.ndim() != 3) {
    throw std::invalid_argument("gains: expected an array of shape (N, nu, nx), got " +
                                (g ? std::to_string(g.ndim()) + " dimensions" : std::string("no array")));
  }
  std::vector<Eigen::MatrixXd> out(g.shape(0), Eigen::MatrixXd(g.shape(1), g.shape(2)));
  auto r = g.unchecked<3>();
  for (py::ssize_t k = 0; k < g.shape(0); ++k) {
    for (py::ssize_t i = 0; i < g.shape(1); ++i) {
      for (py::ssize_t j = 0; j < g.shape(2); ++j) out[k](i, j) = r(k, i, j);
    }
  }
  return out;
}

}  // namespace trellis::python
