// python/src/bind_funnel.cpp — analysis/funnel.hpp and cost_to_go.hpp: the cost-to-go table S(t)
// and estimate_funnel, the same function as `trellis funnel`, its result as arrays (time first:
// per start time and level (S, L); per sample (G, ...)).
#include "common.hpp"
#include "control_common.hpp"

#include "trellis/analysis/funnel.hpp"

#include <optional>
#include <string>
#include <vector>

namespace trellis::python {

void bindFunnel(py::module_& m) {
  py::class_<CostToGo>(m, "CostToGo",
      "The Riccati cost-to-go S(t) (nx, nx) at ascending times, linear in between; V(t, dx) = "
      "dx^T S(t) dx. As arrays: times (N,), S (N, nx, nx). CSV: what `trellis gains --cost-to-go` "
      "writes (the upper triangle, columns S[<state>|<state>]).")
      .def(py::init([](const RealVector<"times">& times, const py::object& S) {
             return CostToGo(Eigen::VectorXd(times.ref), gainsFromArray(S));
           }),
           py::arg("times"), py::arg("S"), "times (N,) strictly increasing; S (N, nx, nx) symmetric. Raises TrajectoryError.")
      .def_static("read_csv", &CostToGo::readCsvFile, py::arg("path"))
      .def("write_csv", &CostToGo::writeCsvFile, py::arg("path"))
      .def_property_readonly("nx", &CostToGo::nx)
      .def_property_readonly("times", [](const CostToGo& c) { return toArray(c.times()); })
      .def_property_readonly("S", [](const CostToGo& c) { return toArray3(c.matrices(), c.nx(), c.nx()); })
      .def("evaluate", [](const CostToGo& c, double t) { return toArray(c.evaluate(t)); }, py::arg("t"),
           "S(t) (nx, nx)")
      .def("level", [](const CostToGo& c, double t, const RealVector<"dx">& dx) {
             return c.level(t, Eigen::VectorXd(dx.ref));
           },
           py::arg("t"), py::arg("dx"), "V(t, dx) = dx^T S(t) dx")
      .def("__len__", &CostToGo::size);

  bindStatus<FunnelCode>(m, "FunnelStatus",
      "Status of a funnel run (code: ok, sample_error: a sample could not be run; index: its "
      "global index). Failing starts are results, not a failed run.");
  py::class_<FunnelResult>(m, "FunnelResult",
      "A funnel estimate: per start time s and level j (arrays (S, L)): samples, successes; rho "
      "(S,): the largest level with no failure at it or below; failure_bound: 1 - (1 - "
      "confidence)^(1/N); worst_failure (S,): the global index of the lowest level's first "
      "failure (-1: none); per sample (G = S L N, by index): sample_start, sample_level, dx0 (G, "
      "nx), success, code (names), final_level (V(T); NaN when the simulation failed).")
      .def_readonly("status", &FunnelResult::status)
      .def_property_readonly("ok", &FunnelResult::ok)
      .def_property_readonly("start_times", [](const FunnelResult& r) {
        return toArray(Eigen::Map<const Eigen::VectorXd>(r.startTimes.data(), static_cast<Eigen::Index>(r.startTimes.size())));
      })
      .def_property_readonly("levels", [](const FunnelResult& r) {
        return toArray(Eigen::Map<const Eigen::VectorXd>(r.levels.data(), static_cast<Eigen::Index>(r.levels.size())));
      })
      .def_readonly("goal_level", &FunnelResult::goalLevel)
      .def_readonly("confidence", &FunnelResult::confidence)
      .def_readonly("failure_bound", &FunnelResult::failureBound)
      .def_property_readonly("samples", [](const FunnelResult& r) {
        py::array_t<long> a({static_cast<py::ssize_t>(r.startTimes.size()), static_cast<py::ssize_t>(r.levels.size())});
        auto w = a.mutable_unchecked<2>();
        for (std::size_t k = 0; k < r.cells.size(); ++k) w(k / r.levels.size(), k % r.levels.size()) = r.cells[k].samples;
        return a;
      })
      .def_property_readonly("successes", [](const FunnelResult& r) {
        py::array_t<long> a({static_cast<py::ssize_t>(r.startTimes.size()), static_cast<py::ssize_t>(r.levels.size())});
        auto w = a.mutable_unchecked<2>();
        for (std::size_t k = 0; k < r.cells.size(); ++k) w(k / r.levels.size(), k % r.levels.size()) = r.cells[k].successes;
        return a;
      })
      .def_property_readonly("rho", [](const FunnelResult& r) { return toArray(r.rho); })
      .def_property_readonly("worst_failure", [](const FunnelResult& r) {
        return py::array_t<long>(static_cast<py::ssize_t>(r.worstFailure.size()), r.worstFailure.data());
      })
      .def_property_readonly("sample_start", [](const FunnelResult& r) {
        py::array_t<int> a(static_cast<py::ssize_t>(r.samples.size()));
        for (std::size_t k = 0; k < r.samples.size(); ++k) a.mutable_at(k) = r.samples[k].start;
        return a;
      })
      .def_property_readonly("sample_level", [](const FunnelResult& r) {
        py::array_t<int> a(static_cast<py::ssize_t>(r.samples.size()));
        for (std::size_t k = 0; k < r.samples.size(); ++k) a.mutable_at(k) = r.samples[k].level;
        return a;
      })
      .def_property_readonly("dx0", [](const FunnelResult& r) {
        const Eigen::Index nx = r.samples.empty() ? 0 : r.samples.front().dx0.size();
        Eigen::MatrixXd dx(static_cast<Eigen::Index>(r.samples.size()), nx);
        for (std::size_t k = 0; k < r.samples.size(); ++k) dx.row(static_cast<Eigen::Index>(k)) = r.samples[k].dx0.transpose();
        return toArray(dx);
      })
      .def_property_readonly("success", [](const FunnelResult& r) {
        py::array_t<bool> a(static_cast<py::ssize_t>(r.samples.size()));
        for (std::size_t k = 0; k < r.samples.size(); ++k) a.mutable_at(k) = r.samples[k].success;
        return a;
      })
      .def_property_readonly("code", [](const FunnelResult& r) {
        std::vector<std::string> codes;
        for (const FunnelSample& s : r.samples) codes.emplace_back(toString(s.code));
        return codes;
      })
      .def_property_readonly("final_level", [](const FunnelResult& r) {
        Eigen::VectorXd v(static_cast<Eigen::Index>(r.samples.size()));
        for (std::size_t k = 0; k < r.samples.size(); ++k) v(static_cast<Eigen::Index>(k)) = r.samples[k].finalLevel;
        return toArray(v);
      })
      .def("describe", &FunnelResult::describe)
      .def("json", &FunnelResult::json)
      .def("__repr__", [](const FunnelResult& r) { return "<FunnelResult " + r.status.describe() + ">"; });

  m.def("estimate_funnel",
        [](const Model& model, const Trajectory& reference, const GainSchedule& gains, const CostToGo& costToGo,
           std::vector<double> levels, long samples, std::uint64_t seed, std::vector<double> startTimes,
           double goalLevel, double confidence, int threads, const std::optional<SimulationOptions>& options) {
          FunnelOptions o;
          o.levels = std::move(levels);
          o.samples = samples;
          o.seed = seed;
          o.startTimes = std::move(startTimes);
          o.goalLevel = goalLevel;
          o.confidence = confidence;
          o.threads = threads;
          o.simulation = options.value_or(SimulationOptions{});
          return withoutGil([&] { return estimateFunnel(model, reference, gains, costToGo, o); });
        },
        py::arg("model"), py::arg("reference"), py::arg("gains"), py::arg("cost_to_go"), py::kw_only(),
        py::arg("levels"), py::arg("samples") = 100, py::arg("seed") = 1,
        py::arg("start_times") = std::vector<double>{}, py::arg("goal_level") = 0.0, py::arg("confidence") = 0.95,
        py::arg("threads") = 0, py::arg("options") = py::none(),
        "The funnel of u = sat(u_ref - K (x - x_ref)) in V = dx^T S dx, as `trellis funnel`: for each "
        "start time (reference knots; default its start) and level rho in `levels`, `samples` starts "
        "on V = rho simulated to the end (options: SimulationOptions, e.g. input bounds); success: "
        "ok and V(T) <= goal_level (0: the smallest level). Sample g's direction depends only on "
        "(seed, g): the result is the same for any `threads`. Returns a FunnelResult (arrays).");
}

}  // namespace trellis::python
