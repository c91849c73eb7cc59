#include <trellis/core.hpp>
#include <iostream>

int main() {
  trellis::ModelBuilder b("pendulum");
  b.addFrame("pivot", "world", trellis::Transform::rz("theta"));            // joint θ
  b.addFrame("bob", "pivot", trellis::Transform::ty(-1.0), trellis::Mass{1.0});
  b.addGravity({0.0, -9.81, 0.0});
  b.addConfigForce("theta", "torque");                                        // input u = torque on θ
  const trellis::Model model = std::move(b).finalize();  // throws trellis::ModelError, naming the field
  trellis::Data data(model);                             // every buffer sized here, once
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 0.3), dq = Eigen::VectorXd::Zero(1),
                        u = Eigen::VectorXd::Zero(1);
  if (!trellis::computeLinearization(model, data, q, dq, u).ok()) return 1;  // no allocation
  std::cout << "A =\n" << data.A << "\nB =\n" << data.B << "\n";  // [[0, 1], [-9.81 cos 0.3, 0]], [0; 1]
}
