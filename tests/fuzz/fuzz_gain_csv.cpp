// fuzz_gain_csv.cpp — the gain-schedule CSV reader (GainSchedule::readCsv): bad text is a
// TrajectoryError; a schedule that reads is written and read again to the same numbers.
#include "fuzz_support.hpp"

#include "trellis/core/gain_schedule.hpp"

#include <cstdint>
#include <sstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    std::istringstream in(text);
    const trellis::GainSchedule schedule = trellis::GainSchedule::readCsv(in, "<fuzz>");
    std::ostringstream out;
    schedule.writeCsv(out);
    std::istringstream again(out.str());
    const trellis::GainSchedule copy = trellis::GainSchedule::readCsv(again, "<round trip>");
    bool same = copy.size() == schedule.size() && copy.nu() == schedule.nu() && copy.nx() == schedule.nx() &&
                copy.times() == schedule.times();
    for (int k = 0; same && k < schedule.size(); ++k) same = copy.gains()[k] == schedule.gains()[k];
    if (!same) trellis::fuzz::finding("the CSV round trip changed the gain schedule", out.str().c_str());
  });
  return 0;
}
