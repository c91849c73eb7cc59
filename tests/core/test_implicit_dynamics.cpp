// tests/core/test_implicit_dynamics.cpp — computeImplicitDynamics (linearization.hpp): the
// equations of motion as residuals at a given q̈ and λ, and their exact first derivatives.
// Legs: r and c against the data members' closed form M q̈ + b − Aᵀλ, A q̈ + Ȧ q̇; zero at the
// forward solution; ∂r/∂[q; q̇], ∂c/∂[q; q̇] against central differences at states away from the
// forward solution (where the forward linearization cannot be the answer); and at the forward
// solution against the forward linearization, an independent route:
// M ∂q̈/∂x − Aᵀ ∂λ/∂x = −∂r/∂x and A ∂q̈/∂x = −∂c/∂x.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/second_order.hpp>

#include <random>
#include <string>

using namespace trellis;
using namespace trellis::test;

namespace {

void checkModel(const std::string& name, const Model& model, std::uint32_t seed) {
  INFO(name);
  const int n = model.nq(), nc = model.nc();
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  Data data(model), work(model);
  ImplicitDynamics id(model), idWork(model);
  for (int trial = 0; trial < 3; ++trial) {
    const State s = randomState(model, rng);
    Eigen::VectorXd qdd(n), lambda(nc);
    for (int i = 0; i < n; ++i) qdd(i) = normal(rng);
    for (int i = 0; i < nc; ++i) lambda(i) = normal(rng);
    REQUIRE(computeImplicitDynamics(model, data, s.q, s.dq, qdd, s.u, lambda, id).ok());

    // r, c against the closed form from the data members (the forward dynamics' own b).
    REQUIRE(computeDynamics(model, work, s.q, s.dq, s.u).ok());
    const Eigen::VectorXd rRef = work.M * qdd + work.bias - work.constraintJacobian.transpose() * lambda;
    const Eigen::VectorXd cRef = work.constraintJacobian * qdd + work.constraintDrift;
    const double rScale = (work.M.cwiseAbs() * qdd.cwiseAbs()).maxCoeff() + work.bias.cwiseAbs().maxCoeff() +
                          (work.constraintJacobian.transpose().cwiseAbs() * lambda.cwiseAbs()).maxCoeff();
    CHECK((id.r - rRef).cwiseAbs().maxCoeff() <= 1e-12 * rScale);
    if (nc > 0) CHECK((id.c - cRef).cwiseAbs().maxCoeff() <= 1e-12 * (1.0 + cRef.cwiseAbs().maxCoeff()));
    CHECK((data.M - work.M).cwiseAbs().maxCoeff() <= 1e-14 * work.M.cwiseAbs().maxCoeff());

    // Derivatives against central differences of the function itself, at this (q̈, λ).
    Eigen::VectorXd x(2 * n);
    x << s.q, s.dq;
    const auto residual = [&](const Eigen::VectorXd& y) -> Eigen::VectorXd {
      Eigen::VectorXd out(n + nc);
      computeImplicitDynamics(model, work, y.head(n), y.tail(n), qdd, s.u, lambda, idWork);
      out << idWork.r, idWork.c;
      return out;
    };
    const Eigen::MatrixXd J = centralDifferenceJacobian(residual, x);
    Eigen::MatrixXd exact(n + nc, 2 * n);
    exact << id.dr_dx, id.dc_dx;
    const double scale = J.cwiseAbs().maxCoeff();
    INFO("trial " << trial << ": |exact − differences| " << (exact - J).cwiseAbs().maxCoeff() << " of " << scale);
    CHECK((exact - J).cwiseAbs().maxCoeff() <= 1e-6 * scale);

    // At the forward solution r = c = 0 and the derivatives agree with the forward linearization.
    REQUIRE(computeLinearization(model, work, s.q, s.dq, s.u).ok());
    const Eigen::VectorXd qddF = work.qdd, lambdaF = work.lambda;
    const Eigen::MatrixXd dqdd = work.A.bottomRows(n), dlam = nc > 0 ? Eigen::MatrixXd(work.dlambda_dx.leftCols(2 * n))
                                                                     : Eigen::MatrixXd(0, 2 * n);
    const Eigen::MatrixXd M = work.M, Ac = work.constraintJacobian;
    REQUIRE(computeImplicitDynamics(model, data, s.q, s.dq, qddF, s.u, lambdaF, id).ok());
    CHECK(id.r.cwiseAbs().maxCoeff() <= 1e-10 * (1.0 + rScale));
    if (nc > 0) CHECK(id.c.cwiseAbs().maxCoeff() <= 1e-10 * (1.0 + cRef.cwiseAbs().maxCoeff()));
    Eigen::MatrixXd lhs = M * dqdd;
    if (nc > 0) lhs -= Ac.transpose() * dlam;
    const double lhsScale = (M.cwiseAbs() * dqdd.cwiseAbs()).maxCoeff() + 1e-300;
    CHECK((lhs + id.dr_dx).cwiseAbs().maxCoeff() <= 1e-9 * lhsScale);
    if (nc > 0) {
      const Eigen::MatrixXd clhs = Ac * dqdd + id.dc_dx;
      CHECK(clhs.cwiseAbs().maxCoeff() <= 1e-9 * ((Ac.cwiseAbs() * dqdd.cwiseAbs()).maxCoeff() + 1.0));
    }
  }
}

/// computeImplicitSecondOrder against central differences of the exact first derivatives:
/// ∇_z φ = [νᵀ ∂r/∂x + ηᵀ ∂c/∂x, −νᵀ B_u] and ∇_y φ = [M ν + Aᵀη; −A ν] (φ = νᵀ r + ηᵀ c).
void checkSecondOrder(const std::string& name, const Model& model, std::uint32_t seed) {
  INFO(name);
  const int n = model.nq(), nc = model.nc(), m = model.nu(), N = 2 * n + m;
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  Data data(model), work(model);
  SecondOrderWorkspace ws(model, false, true);
  ImplicitDynamics id(model);
  Eigen::MatrixXd Hzz(N, N), Hyz(n + nc, 2 * n);
  for (int trial = 0; trial < 2; ++trial) {
    const State s = randomState(model, rng);
    Eigen::VectorXd qdd(n), lambda(nc), nu(n), eta(nc);
    for (int i = 0; i < n; ++i) qdd(i) = normal(rng), nu(i) = normal(rng);
    for (int i = 0; i < nc; ++i) lambda(i) = normal(rng), eta(i) = normal(rng);
    REQUIRE(computeImplicitSecondOrder(model, data, ws, s.q, s.dq, qdd, s.u, lambda, nu, eta, Hzz, Hyz).ok());
    CHECK((Hzz - Hzz.transpose()).cwiseAbs().maxCoeff() <= 1e-12 * (1.0 + Hzz.cwiseAbs().maxCoeff()));
    Eigen::VectorXd z(N);
    z << s.q, s.dq, s.u;
    const auto gradZ = [&](const Eigen::VectorXd& y) -> Eigen::VectorXd {
      computeImplicitDynamics(model, work, y.head(n), y.segment(n, n), qdd, y.tail(m), lambda, id);
      Eigen::VectorXd g(N);
      g.head(2 * n) = id.dr_dx.transpose() * nu + id.dc_dx.transpose() * eta;
      g.tail(m) = -work.inputMatrix.transpose() * nu;
      return g;
    };
    const auto gradY = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd {
      computeImplicitDynamics(model, work, x.head(n), x.tail(n), qdd, s.u, lambda, id);
      Eigen::VectorXd g(n + nc);
      g.head(n) = work.M * nu + work.constraintJacobian.transpose() * eta;
      g.tail(nc) = -work.constraintJacobian * nu;
      return g;
    };
    const Eigen::MatrixXd fdZ = centralDifferenceJacobian(gradZ, z);
    Eigen::VectorXd x(2 * n);
    x << s.q, s.dq;
    const Eigen::MatrixXd fdY = centralDifferenceJacobian(gradY, x);
    const double sz = fdZ.cwiseAbs().maxCoeff(), sy = fdY.cwiseAbs().maxCoeff() + 1e-300;
    INFO("trial " << trial << ": Hzz off by " << (Hzz - fdZ).cwiseAbs().maxCoeff() << " of " << sz << ", Hyz off by "
                  << (Hyz - fdY).cwiseAbs().maxCoeff() << " of " << sy);
    CHECK((Hzz - fdZ).cwiseAbs().maxCoeff() <= 1e-6 * sz);
    CHECK((Hyz - fdY).cwiseAbs().maxCoeff() <= 1e-6 * sy);
    CHECK(Hzz.bottomRightCorner(m, m).isZero(0.0));
  }
}

}  // namespace

TEST_CASE("implicit dynamics: second derivatives of the weighted residuals", "[implicit_dynamics][second_order]") {
  checkSecondOrder("kitchen sink (every constraint kind, springs, dampers, wrenches)", kitchenSink().model, 13);
  checkSecondOrder("planar chain", planarChain(4).model, 14);
  checkSecondOrder("the paper's pendulum", paperPendulum().model, 15);
  Scene hand = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand_ball.json");
  checkSecondOrder("hand and free ball", hand.model, 16);
  // A workspace that runs the tree pass (a plain chain: inertia, gravity only) is refused by name.
  const Model chain = planarChain(4).model;
  SecondOrderWorkspace tree(chain, false);
  Data data(chain);
  const int n = chain.nq(), N = 2 * n + chain.nu();
  Eigen::MatrixXd Hzz(N, N), Hyz(n, 2 * n);
  const Eigen::VectorXd zn = Eigen::VectorXd::Zero(n), zc(0), zu = Eigen::VectorXd::Zero(chain.nu());
  CHECK_THROWS_WITH(computeImplicitSecondOrder(chain, data, tree, zn, zn, zn, zu, zc, zn, zc, Hzz, Hyz),
                    Catch::Contains("recording"));
}

TEST_CASE("implicit dynamics: residuals and their derivatives at a given acceleration and force",
          "[implicit_dynamics]") {
  checkModel("kitchen sink (every constraint kind, springs, dampers, wrenches)", kitchenSink().model, 3);
  checkModel("kitchen sink without constraints", kitchenSink(3, false).model, 4);
  checkModel("planar chain", planarChain(5).model, 5);
  checkModel("the paper's pendulum", paperPendulum().model, 6);
  // The hand holding the free ball: tendons, point-on-plane contacts, a floating body.
  Scene hand = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand_ball.json");
  checkModel("hand and free ball", hand.model, 7);
}

TEST_CASE("implicit dynamics: bad sizes and non-finite inputs", "[implicit_dynamics]") {
  const Model model = kitchenSink().model;
  Data data(model);
  ImplicitDynamics id(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq()), u = Eigen::VectorXd::Zero(model.nu()),
                        lambda = Eigen::VectorXd::Zero(model.nc());
  CHECK_THROWS_WITH(computeImplicitDynamics(model, data, q, q, Eigen::VectorXd::Zero(1), u, lambda, id),
                    Catch::Contains("qdd"));
  CHECK_THROWS_WITH(computeImplicitDynamics(model, data, q, q, q, u, Eigen::VectorXd::Zero(model.nc() + 1), id),
                    Catch::Contains("lambda"));
  ImplicitDynamics wrong;
  CHECK_THROWS_WITH(computeImplicitDynamics(model, data, q, q, q, u, lambda, wrong), Catch::Contains("out"));
  Eigen::VectorXd bad = q;
  bad(0) = std::nan("");
  const auto st = computeImplicitDynamics(model, data, q, q, bad, u, lambda, id);
  CHECK(st.code == DynamicsStatus::Code::kNonFinite);
  CHECK(st.message.find("qdd") != std::string::npos);
}
