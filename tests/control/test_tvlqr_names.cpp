// test_tvlqr_names.cpp — enum names live in the library once (issue 10): every name the CLI,
// the benchmarks and the Python module use round-trips through toString / parse, and a bad name
// is refused with the list of valid ones.
#include <trellis/control.hpp>

#include <catch2/catch.hpp>

#include <limits>
#include <stdexcept>
#include <string>

TEST_CASE("names: Riccati and integration methods round-trip; bad names list the valid ones",
          "[names]") {
  using trellis::IntegrationMethod;
  using trellis::RiccatiMethod;
  for (RiccatiMethod m : {RiccatiMethod::kBDF, RiccatiMethod::kAdams, RiccatiMethod::kFactored}) {
    CHECK(trellis::parseRiccatiMethod(trellis::toString(m)) == m);
  }
  CHECK(std::string(trellis::toString(RiccatiMethod::kFactored)) == "factored");
  CHECK_THROWS_AS(trellis::parseRiccatiMethod("euler"), std::invalid_argument);
  CHECK_THROWS_WITH(trellis::parseRiccatiMethod("euler"),
                    Catch::Contains("'euler' is not one of bdf, adams, factored"));
  for (IntegrationMethod m : {IntegrationMethod::kAdams, IntegrationMethod::kBDF}) {
    CHECK(trellis::parseIntegrationMethod(trellis::toString(m)) == m);
  }
  CHECK_THROWS_WITH(trellis::parseIntegrationMethod("BDF"),
                    Catch::Contains("'BDF' is not one of adams, bdf, radau"));
  // LqrCode names are distinct and non-empty (they appear in messages and JSON).
  const std::string names[] = {trellis::toString(trellis::LqrCode::kOk),
                               trellis::toString(trellis::LqrCode::kNotStabilizable),
                               trellis::toString(trellis::LqrCode::kNoStabilizingSolution),
                               trellis::toString(trellis::LqrCode::kNoConvergence)};
  CHECK(names[0] == "ok");
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) CHECK(names[i] != names[j]);
}

TEST_CASE("the S >= 0 check of a solution's spectrum is relative to its size", "[tvlqr]") {
  CHECK(trellis::isSemidefiniteToRoundoff(0.0, 0.0));          // not tracked
  CHECK(trellis::isSemidefiniteToRoundoff(1e-3, 10.0));        // definite
  CHECK(trellis::isSemidefiniteToRoundoff(-1e-6, 10.0));       // round-off: −1e-7 relative
  CHECK_FALSE(trellis::isSemidefiniteToRoundoff(-1e-4, 10.0)); // −1e-5 relative
  // The same spectra in other units give the same verdicts.
  CHECK(trellis::isSemidefiniteToRoundoff(-1e-12, 1e-5));
  CHECK_FALSE(trellis::isSemidefiniteToRoundoff(-1e-10, 1e-5));
  CHECK_FALSE(trellis::isSemidefiniteToRoundoff(-1.0, std::numeric_limits<double>::infinity()));
}
