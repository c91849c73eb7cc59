// examples/hand/job_progress.hpp — the hand jobs' progress lines and stage table (hand_main_job,
// hand_hold_job): "[i/N] stage ..." when a stage starts, "done in T s: detail" when it ends, and
// the summary's table of stage times with the whole job's (column widths counted in characters,
// not bytes: stage names may hold "q''", "≤", "σ").
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

namespace trellis::hand {

using JobClock = std::chrono::steady_clock;

inline double secondsSince(JobClock::time_point start) {
  return std::chrono::duration<double>(JobClock::now() - start).count();
}

/// printf-style text of up to four numbers (the jobs' detail lines).
inline std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0, double d = 0.0) {
  char buffer[512];
  std::snprintf(buffer, sizeof buffer, fmt, a, b, c, d);
  return buffer;
}

struct StageTime {
  std::string name;
  double seconds;
};

class Progress {
 public:
  explicit Progress(int total) : total_(total) {}
  void begin(const std::string& what) {
    ++index_;
    what_ = what;
    start_ = JobClock::now();
    std::printf("[%d/%d] %s ...\n", index_, total_, what.c_str());
    std::fflush(stdout);
  }
  double end(const std::string& detail = "") {
    const double s = secondsSince(start_);
    std::printf("      done in %.3f s%s%s\n", s, detail.empty() ? "" : ": ", detail.c_str());
    std::fflush(stdout);
    stages.push_back({what_, s});
    return s;
  }
  /// The stage table: a header row, one row per stage, and "whole job".
  void table(std::ostringstream& out, double wholeJob) const {
    const auto width = [](const std::string& text) {
      return static_cast<int>(std::count_if(text.begin(), text.end(), [](char c) { return (c & 0xC0) != 0x80; }));
    };
    int nameWidth = width("whole job");
    for (const StageTime& s : stages) nameWidth = std::max(nameWidth, width(s.name));
    const auto row = [&](const std::string& name, const std::string& value) {
      out << "  " << name << std::string(nameWidth - width(name) + 2, ' ') << value << '\n';
    };
    row("stage", "time [s]");
    for (const StageTime& s : stages) row(s.name, format("%8.3f", s.seconds));
    row("whole job", format("%8.3f", wholeJob));
  }
  std::vector<StageTime> stages;

 private:
  int total_, index_ = 0;
  std::string what_;
  JobClock::time_point start_;
};

}  // namespace trellis::hand
