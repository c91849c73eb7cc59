// Builds a simple pendulum through the installed headers and checks its linearization:
// θ̈ = −(g/l) sin θ, so A = [[0, 1], [−(g/l) cos θ, 0]].
#include <trellis/control.hpp>
#include <trellis/core.hpp>
#include <trellis/viewer/view.hpp>

#include <cmath>
#include <iostream>
#include <utility>

int main() {
  const double g = 9.81, l = 1.0, theta = 0.3;

  trellis::ModelBuilder builder("pendulum");
  builder.addFrame("pivot", "world", trellis::Transform::rz("theta"));
  builder.addFrame("bob", "pivot", trellis::Transform::ty(-l), trellis::Mass{1.0});
  builder.addGravity({0.0, -g, 0.0});
  const trellis::Model model = std::move(builder).finalize();

  trellis::Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, theta);
  const Eigen::VectorXd dq = Eigen::VectorXd::Zero(1);
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model.nu());
  const trellis::DynamicsStatus status = trellis::computeLinearization(model, data, q, dq, u);

  std::cout << "A =\n" << data.A << "\n";
  if (!status.ok()) {
    std::cerr << "computeLinearization failed: " << status.message << "\n";
    return 1;
  }
  if (data.A.rows() != 2 || data.A.cols() != 2 || !data.A.allFinite()) {
    std::cerr << "A is not a finite 2x2 matrix\n";
    return 1;
  }
  const double expected = -g / l * std::cos(theta);
  if (std::abs(data.A(1, 0) - expected) > 1e-9 * std::abs(expected) || data.A(0, 1) != 1.0) {
    std::cerr << "A(1,0) = " << data.A(1, 0) << ", expected " << expected << "\n";
    return 1;
  }
  // trellis::control through the installed package: the double integrator's CARE in closed form,
  // Q = I, R = 1 → S₁₂ = 1, S₂₂ = √3, K = [1, √3].
  Eigen::MatrixXd Ad(2, 2), Bd(2, 1);
  Ad << 0, 1, 0, 0;
  Bd << 0, 1;
  const trellis::LqrResult lqr = trellis::solveCare(Ad, Bd, Eigen::MatrixXd::Identity(2, 2),
                                                    Eigen::MatrixXd::Identity(1, 1));
  if (!lqr.ok() || std::abs(lqr.K(0, 0) - 1.0) > 1e-9 || std::abs(lqr.K(0, 1) - std::sqrt(3.0)) > 1e-9) {
    std::cerr << "solveCare: " << lqr.status.describe() << " K = " << lqr.K << "\n";
    return 1;
  }
  // trellis::viewer through the installed package, with the installed three.js and its licence.
  trellis::Scene scene{model, q, dq, u, "pendulum", "", {}};
  trellis::ViewOptions options;
  options.threeDirectory = TRELLIS_THREE_DIR;
  const std::string page = trellis::renderView(scene, q, {}, options);
  if (page.find("OrbitControls") == std::string::npos ||
      page.find(std::string(TRELLIS_THREE_DIR) + "/LICENSE") == std::string::npos) {
    std::cerr << "renderView: the page lacks three.js or its licence notice\n";
    return 1;
  }
  std::cout << "downstream: ok\n";
  return 0;
}
