// fuzz_cost_to_go_csv.cpp — the cost-to-go CSV reader (CostToGo::readCsv, what `trellis funnel
// --cost-to-go` reads): bad text is a TrajectoryError; a table that reads is written and read
// again to the same numbers and names.
#include "fuzz_support.hpp"

#include "trellis/analysis/cost_to_go.hpp"

#include <cstdint>
#include <sstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    std::istringstream in(text);
    const trellis::CostToGo table = trellis::CostToGo::readCsv(in, "<fuzz>");
    std::ostringstream out;
    table.writeCsv(out);
    std::istringstream again(out.str());
    const trellis::CostToGo copy = trellis::CostToGo::readCsv(again, "<round trip>");
    bool same = copy.size() == table.size() && copy.nx() == table.nx() && copy.times() == table.times() &&
                copy.stateNames() == table.stateNames();
    for (int k = 0; same && k < table.size(); ++k) same = copy.matrices()[k] == table.matrices()[k];
    if (!same) trellis::fuzz::finding("the CSV round trip changed the cost-to-go", out.str().c_str());
  });
  return 0;
}
