// tests/core/test_reports.cpp — the names of the core's enums (one table each, enum_names.hpp)
// and the describe() / json() reports of the core's results (status.hpp, report_json.hpp).
#include <catch2/catch.hpp>

#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/numdiff.hpp>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

/// Every value of the table maps to its name and back, and the names are distinct.
template <class E>
void checkRoundTrip(const std::vector<std::string>& expected) {
  std::vector<std::string> names;
  for (const EnumName<E>& entry : enumNames(E{})) {
    names.emplace_back(entry.name);
    CHECK(std::string(toString(entry.value)) == entry.name);
    CHECK(parseEnum<E>(entry.name, "field") == entry.value);
  }
  CHECK(names == expected);
  CHECK_THROWS_WITH(parseEnum<E>("no_such_name", "field"),
                    Catch::Matchers::Contains("field 'no_such_name' is not one of"));
}

}  // namespace

TEST_CASE("Core enums: one name table each, parsed and printed alike", "[status][names]") {
  checkRoundTrip<DynamicsCode>({"ok", "redundant_constraints", "singular_mass_matrix", "singular_constraints", "non_finite"});
  checkRoundTrip<EquilibriumCode>({"ok", "not_converged", "dynamics_failure"});
  checkRoundTrip<InverseDynamicsCode>({"ok", "unreachable", "inadmissible_acceleration", "input_bounds", "non_finite"});
  checkRoundTrip<ProjectionCode>({"ok", "not_converged", "non_finite"});
  checkRoundTrip<TransformType>({"tx", "ty", "tz", "rx", "ry", "rz", "const_se3", "r_axis", "t_axis"});
  checkRoundTrip<ConstraintType>({"distance", "point", "point_on_plane", "knife_edge", "coordinate_coupling"});
  checkRoundTrip<GainInterpolation>({"linear", "cubic"});
  checkRoundTrip<DifferenceScheme>({"forward", "central", "central4"});
}

TEST_CASE("Core results: describe() is one line, json() an object with the status keys", "[status][reports]") {
  const TestSystem sys = paperPendulum(1);
  const Model& model = sys.model;
  Data data(model);
  const Eigen::VectorXd q = (Eigen::VectorXd(2) << 0.3, -0.4).finished();
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model.nu());
  const auto statusKeys = [](const nlohmann::json& j, bool ok) {
    for (const char* key : {"status", "ok", "message", "t", "index"}) CHECK(j.contains(key));
    CHECK(j["ok"].get<bool>() == ok);
  };

  SECTION("DynamicsStatus (a Status<DynamicsCode>)") {
    const ProjectionResult p = projectState(model, data, q, zero);
    REQUIRE(p.ok());
    const DynamicsStatus s = computeDynamics(model, data, p.q, p.dq, u);
    REQUIRE(s.ok());
    CHECK(std::string(s.name()) == "ok");
    CHECK(s.describe().find('\n') == std::string::npos);
    CHECK(s.describe().rfind("ok", 0) == 0);
    const nlohmann::json j = nlohmann::json::parse(s.json());
    statusKeys(j, true);
    CHECK(j["constraint_rank"].get<int>() == 1);
    DynamicsStatus bad;
    bad.set(DynamicsCode::kSingularMassMatrix, "joint 'x' moves no mass");
    CHECK(!bad.ok());
    CHECK(bad.describe().rfind("singular_mass_matrix: joint 'x' moves no mass", 0) == 0);
    CHECK(nlohmann::json::parse(bad.json())["status"] == "singular_mass_matrix");
  }
  SECTION("ProjectionResult") {
    const ProjectionResult r = projectState(model, data, q, zero);
    REQUIRE(r.ok());
    CHECK(r.describe().rfind("ok (", 0) == 0);
    const nlohmann::json j = nlohmann::json::parse(r.json());
    statusKeys(j, true);
    CHECK(j["q"].size() == 2);
    CHECK(j["h_after"].get<double>() == r.positionResidual);
  }
  SECTION("EquilibriumResult") {
    const EquilibriumResult r = findEquilibrium(model, data, q, u);
    const nlohmann::json j = nlohmann::json::parse(r.json());
    statusKeys(j, r.ok());
    CHECK(j["status"] == r.status.name());
    CHECK(j["iterations"].get<int>() == r.iterations);
    CHECK(r.describe().rfind(r.status.name(), 0) == 0);
  }
  SECTION("InverseDynamicsResult") {
    const ProjectionResult p = projectState(model, data, q, zero);
    REQUIRE(computeDynamics(model, data, p.q, p.dq, u).ok());
    const Eigen::VectorXd qdd = data.qdd;
    const InverseDynamicsResult r = computeInverseDynamics(model, data, p.q, p.dq, qdd);
    REQUIRE(r.ok());
    const nlohmann::json j = nlohmann::json::parse(r.json());
    statusKeys(j, true);
    CHECK(j["u"].size() == 1);
    CHECK(j["u"][0].get<double>() == Approx(0.0).margin(1e-9));
    CHECK(r.describe().find('\n') == std::string::npos);
  }
}
