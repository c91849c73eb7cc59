// python/src/bind_hand.cpp — trellis_mech.hand: the hand's reference motion (examples/hand), for
// the Python version of the main job. Built only when the examples are (TRELLIS_PYTHON_HAND).
#include "common.hpp"
#include "options.hpp"

#include "reference_motion.hpp"

namespace trellis::python {

void bindHand(py::module_& parent) {
  py::module_ m = parent.def_submodule(
      "hand", "The human hand of examples/scenes/hand.json: its reference motion on the grasp's "
              "constraint manifold with inverse-dynamics tendon tensions (examples/hand).");
  using hand::ReferenceMotion;
  using hand::ReferenceMotionOptions;
  py::class_<ReferenceMotionOptions>(m, "ReferenceMotionOptions",
      "duration (s), knots, drivers (configuration names), amplitudes (rad, one per driver).")
      .def(py::init(&makeFromKwargs<ReferenceMotionOptions>))
      .def_readwrite("duration", &ReferenceMotionOptions::duration)
      .def_readwrite("knots", &ReferenceMotionOptions::knots)
      .def_readwrite("drivers", &ReferenceMotionOptions::drivers)
      .def_readwrite("amplitudes", &ReferenceMotionOptions::amplitudes);
  py::class_<ReferenceMotion>(m, "ReferenceMotion")
      .def_readonly("trajectory", &ReferenceMotion::trajectory)
      .def_property_readonly("accelerations", [](const ReferenceMotion& r) { return toArray(Eigen::MatrixXd(r.accelerations.transpose())); },
                             "(N, n), time first")
      .def_property_readonly("lambda_", [](const ReferenceMotion& r) { return toArray(Eigen::MatrixXd(r.lambda.transpose())); },
                             "(N, nc), time first")
      .def_property_readonly("constraint_residual",
                             [](const ReferenceMotion& r) { return toArray(r.constraintResidual); })
      .def_property_readonly("forward_dynamics_error",
                             [](const ReferenceMotion& r) { return toArray(r.forwardDynamicsError); })
      .def_readonly("ok", &ReferenceMotion::ok)
      .def_readonly("message", &ReferenceMotion::message);
  m.def("make_reference_motion",
        [](const Model& model, const RealVector<"q0">& q0, const std::optional<ReferenceMotionOptions>& o) {
          const Eigen::VectorXd q = q0.ref;
          py::gil_scoped_release release;
          return hand::makeReferenceMotion(model, q, o.value_or(ReferenceMotionOptions{}));
        },
        py::arg("model"), py::arg("q0"), py::kw_only(), py::arg("options") = py::none(),
        "The reference motion from configuration q0 (projected onto h = 0 first).");
}

}  // namespace trellis::python
