// reduced_problem.cpp — see reduced_problem.hpp.
#include "reduced_problem.hpp"

#include <stdexcept>
#include <string>

namespace trellis::detail {

ReferenceStatus ReducedProblem::reducedTerminal(const Eigen::MatrixXd& Qf, double t,
                                                Eigen::MatrixXd& Qfr) const {
  const ReferenceStatus st = evaluator->evaluate(t);
  if (!st.ok()) return st;
  const Eigen::MatrixXd& T = evaluator->T();
  const Eigen::MatrixXd Qr = T.transpose() * Qf * T;
  Qfr = 0.5 * (Qr + Qr.transpose());
  return st;
}

ReducedProblem makeReducedProblem(const Model& model, const TangentBasisTrajectory& basis,
                                  const LqrWeights& weights) {
  ReducedProblem p;
  p.evaluator = std::make_shared<ReducedLinearization>(model, basis);
  const std::shared_ptr<ReducedLinearization> lin = p.evaluator;
  p.linearization = [lin](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    const ReferenceStatus st = lin->evaluate(t);  // a failure: the solver's kCallbackFailure
    if (st.ok()) {
      A = lin->Ar();
      B = lin->Br();
    }
    return st;
  };
  p.weights.R = weights.R;
  p.weights.Rfun = weights.Rfun;
  const Eigen::Index nx = basis.nx();
  struct Scratch {
    Eigen::MatrixXd Q, QT;
  };
  if (basis.isIdentity() && !weights.Qfun) {
    // No constraints: T = I, so Qr = Q, constant — said as such (no callback per t; the sampled
    // integrators see that Q does not move). Exactly symmetric, as the callback's.
    p.weights.Q = weights.Q;
    for (Eigen::Index j = 0; j < nx; ++j)
      for (Eigen::Index i = j + 1; i < nx; ++i) p.weights.Q(i, j) = p.weights.Q(j, i);
    return p;
  }
  auto scratch = std::make_shared<Scratch>();
  p.weights.Qfun = [lin, scratch, Qconst = weights.Q, Qfull = weights.Qfun, nx](double t, Eigen::MatrixXd& Qr) {
    // The solvers ask for Q(t) only after the linearization at the same t succeeded: cached on
    // t, no extra dynamics, and a failure here is a broken solver contract, not a numerical one.
    const ReferenceStatus st = lin->evaluate(t);
    if (!st.ok()) throw std::logic_error("reduced Q(t) requested where the linearization failed: " + st.message);
    const Eigen::MatrixXd& T = lin->T();
    if (Qfull) {
      scratch->Q.setZero(nx, nx);
      Qfull(t, scratch->Q);
      if (scratch->Q.rows() != nx || scratch->Q.cols() != nx) {
        throw std::runtime_error("Q(t) callback returned " + std::to_string(scratch->Q.rows()) + "x" +
                                 std::to_string(scratch->Q.cols()) + ", expected " + std::to_string(nx) +
                                 "x" + std::to_string(nx));
      }
      scratch->QT.noalias() = scratch->Q * T;
    } else {
      scratch->QT.noalias() = Qconst * T;
    }
    Qr.noalias() = T.transpose() * scratch->QT;
    for (Eigen::Index j = 0; j < Qr.cols(); ++j) {  // exactly symmetric: upper triangle mirrored
      for (Eigen::Index i = j + 1; i < Qr.rows(); ++i) Qr(i, j) = Qr(j, i);
    }
  };
  return p;
}

}  // namespace trellis::detail
