// The status vocabulary (status.hpp, enum_names.hpp, detail/report_json.hpp).
#include "trellis/core/detail/report_json.hpp"
#include "trellis/core/status.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <stdexcept>

namespace probe {
enum class Outcome { kOk, kBlowUp, kTooSlow };
inline trellis::EnumNameTable<Outcome> enumNames(Outcome) {
  static constexpr trellis::EnumName<Outcome> table[] = {
      {Outcome::kOk, "ok"}, {Outcome::kBlowUp, "blow_up"}, {Outcome::kTooSlow, "too_slow"}};
  return table;
}
enum class Solve { kSolved, kAcceptable, kFailed };
inline trellis::EnumNameTable<Solve> enumNames(Solve) {
  static constexpr trellis::EnumName<Solve> table[] = {
      {Solve::kSolved, "solved"}, {Solve::kAcceptable, "acceptable"}, {Solve::kFailed, "failed"}};
  return table;
}
constexpr bool isSuccess(Solve s) { return s == Solve::kSolved || s == Solve::kAcceptable; }
}  // namespace probe

using probe::Outcome;
using probe::Solve;

TEST_CASE("enum names: one table gives names, parsing and the list") {
  CHECK(std::string(trellis::toString(Outcome::kBlowUp)) == "blow_up");
  CHECK(std::string(trellis::toString(static_cast<Outcome>(7))) == "unknown");
  CHECK(trellis::parseEnum<Outcome>("too_slow", "--outcome") == Outcome::kTooSlow);
  CHECK(trellis::enumNameList<Outcome>() == "ok, blow_up, too_slow");
  try {
    trellis::parseEnum<Outcome>("fast", "--outcome");
    FAIL("no exception");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()) == "--outcome 'fast' is not one of ok, blow_up, too_slow");
  }
}

TEST_CASE("status: success, describe and the JSON report") {
  trellis::Status<Outcome> s;
  CHECK(s.ok());
  CHECK(s.describe() == "ok");
  s.set(Outcome::kBlowUp, "max |S_ij| = 1e+15", 1.25, 3);
  CHECK_FALSE(s.ok());
  CHECK(s.describe() == "blow_up at t = 1.25 (index 3): max |S_ij| = 1e+15");
  const auto j = trellis::detail::statusJson(s);
  CHECK(j.dump() ==
        R"({"status":"blow_up","ok":false,"message":"max |S_ij| = 1e+15","t":1.25,"index":3})");
  trellis::Status<Outcome> plain;
  CHECK(trellis::detail::statusJson(plain).dump() ==
        R"({"status":"ok","ok":true,"message":"","t":null,"index":null})");

  SECTION("an enum with several success values") {
    trellis::Status<Solve> o;
    CHECK(o.ok());
    o.code = Solve::kAcceptable;
    CHECK(o.ok());
    o.code = Solve::kFailed;
    CHECK_FALSE(o.ok());
  }
  SECTION("numbers round-trip in the line") {
    s.set(Outcome::kTooSlow, "", 0.1 + 0.2);
    CHECK(s.describe() == "too_slow at t = 0.30000000000000004");
    CHECK(trellis::formatStatusNumber(1e-300) == "1e-300");
    // Whole numbers keep their positional form below 1e16 ("50 Hz", not "5e+01 Hz").
    CHECK(trellis::formatStatusNumber(50.0) == "50");
    CHECK(trellis::formatStatusNumber(-1200.0) == "-1200");
    CHECK(trellis::formatStatusNumber(1234.5) == "1234.5");
    CHECK(trellis::formatStatusNumber(2.5e20) == "2.5e+20");
  }
  SECTION("non-finite numbers become null in reports") {
    CHECK(trellis::detail::toJson(std::nan("")).is_null());
    Eigen::MatrixXd m(1, 2);
    m << 1.0, INFINITY;
    CHECK(trellis::detail::toJson(m).dump() == "[[1.0,null]]");
    Eigen::VectorXd v(2);
    v << 2.0, NAN;
    CHECK(trellis::detail::toJson(v).dump() == "[2.0,null]");
  }
}
