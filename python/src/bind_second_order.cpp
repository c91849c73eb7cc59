// python/src/bind_second_order.cpp — the exact second derivatives (trellis/core/second_order.hpp):
// the six tensors of q̈ (and λ's) as NumPy arrays, and the contraction Σ wᵢ ∇²q̈ᵢ + Σ ρ_r ∇²λ_r as
// a function of the weights at one state.
#include "common.hpp"

#include "trellis/core/second_order.hpp"

#include <memory>
#include <optional>

namespace trellis::python {

namespace {

/// The contraction at one state, as a Python callable: h(w, rho=None) → (N, N) array. Holds its
/// own Data and workspace (sized once), so repeated calls allocate only the returned array.
struct Contraction {
  Contraction(ModelPtr m, const VectorRef& q, const VectorRef& dq, const VectorRef& u)
      : model(std::move(m)), data(*model), ws(*model, false), q(model->nq()), dq(model->nq()), u(model->nu()) {
    loadVector(q, this->q, "q", "nq");
    loadVector(dq, this->dq, "dq", "nq");
    loadVector(u, this->u, "u", "nu");
  }
  ModelPtr model;
  Data data;
  SecondOrderWorkspace ws;
  Eigen::VectorXd q, dq, u;
  DynamicsStatus status;
};

}  // namespace

void bindSecondOrder(py::module_& m) {
  m.def(
      "compute_second_order",
      [](const ModelPtr& model, PyData& d, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u) {
        checkSameModel(*model, d);
        DataGuard guard(d);
        loadVector(q, d.q, "q", "nq");
        loadVector(dq, d.dq, "dq", "nq");
        loadVector(u, d.u, "u", "nu");
        SecondOrderWorkspace ws(*model);
        DynamicsStatus status;
        {
          py::gil_scoped_release release;
          status = computeSecondOrderTensors(*model, d.data, ws, d.q, d.dq, d.u);
        }
        const Eigen::Index n = model->nq(), mu = model->nu(), N = 2 * n + mu;
        py::dict out;
        out["status"] = status;
        using Block = SecondOrderWorkspace::Block;
        const std::pair<const char*, Block> blocks[] = {{"d2qdd_dqdq", Block::kQQ},    {"d2qdd_dqddq", Block::kQDq},
                                                        {"d2qdd_ddqddq", Block::kDqDq}, {"d2qdd_dudq", Block::kUQ},
                                                        {"d2qdd_duddq", Block::kUDq},   {"d2qdd_dudu", Block::kUU}};
        for (const auto& [key, block] : blocks) {
          const std::vector<Eigen::MatrixXd> slices = ws.qddBlock(block);
          const Eigen::Index rows = block == Block::kUQ || block == Block::kUDq || block == Block::kUU ? mu : n;
          const Eigen::Index cols = block == Block::kUU ? mu : n;
          out[key] = toArray3(slices, rows, cols);
        }
        out["d2qdd_dz2"] = toArray3(ws.qddHessian, N, N);
        out["d2lambda_dz2"] = toArray3(ws.lambdaHessian, N, N);
        return out;
      },
      py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
      "Exact second derivatives of qdd(q, dq, u) of the constrained system (lambda eliminated) and "
      "of lambda. Returns a dict: 'status' (DynamicsStatus; the arrays are valid when it is ok or "
      "redundant_constraints), the six blocks output index first — 'd2qdd_dqdq' (n, n, n) "
      "[i, j, k] = d2 qdd_i / dq_j dq_k, 'd2qdd_dqddq' (n, n, n) dq_j ddq_k, 'd2qdd_ddqddq' (n, n, n), "
      "'d2qdd_dudq' (n, m, n) du_j dq_k, 'd2qdd_duddq' (n, m, n), 'd2qdd_dudu' (n, m, m) (zero: qdd "
      "is affine in u) — and the whole Hessians over z = [q; dq; u]: 'd2qdd_dz2' (n, N, N), "
      "'d2lambda_dz2' (nc, N, N), N = 2n + m. data holds the linearization at the state afterwards.");

  py::class_<Contraction, std::shared_ptr<Contraction>>(
      m, "SecondOrderContraction",
      "H(w, rho=None) = sum_i w_i Hess_z qdd_i + sum_r rho_r Hess_z lambda_r (N, N) at one state, "
      "without forming the tensors (one adjoint KKT solve and one hyper-dual residual pass per "
      "pair). Make one with second_order_contraction(model, q, dq, u).")
      .def(
          "__call__",
          [](Contraction& c, const RealVector<"w">& w, std::optional<RealVector<"rho">> rho) {
            const Eigen::Index n = c.model->nq(), N = 2 * n + c.model->nu();
            checkSize(w.size(), n, "w", "nq");
            Eigen::VectorXd wv = w.ref, rv;
            if (rho) {
              checkSize(rho->size(), c.model->nc(), "rho", "nc");
              rv = rho->ref;
            }
            Eigen::MatrixXd H(N, N);
            {
              py::gil_scoped_release release;
              c.status = computeSecondOrderContraction(*c.model, c.data, c.ws, c.q, c.dq, c.u, wv, rv, H);
            }
            return toArray(H);
          },
          py::arg("w"), py::arg("rho") = py::none(),
          "The (N, N) contraction for weights w (nq,) on qdd and rho (nc,) on lambda; check .status.")
      .def_property_readonly("status", [](const Contraction& c) { return c.status; },
                             "DynamicsStatus of the last call (the result is valid when ok)");

  m.def(
      "second_order_contraction",
      [](const ModelPtr& model, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u) {
        return std::make_shared<Contraction>(model, q, dq, u);
      },
      py::arg("model"), py::arg("q"), py::arg("dq"), py::arg("u"),
      "The contraction of the exact second derivatives at the state (q, dq, u) as a function "
      "h(w, rho=None) -> (N, N) array, N = 2 nq + nu (see SecondOrderContraction).");
}

}  // namespace trellis::python
