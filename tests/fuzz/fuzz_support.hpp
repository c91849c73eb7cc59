// fuzz_support.hpp — what a fuzz target may and may not do with a hostile input.
//
// A parser given bad input must throw its own error type (ModelError, TrajectoryError, ...: all
// std::runtime_error) with a message. Anything else is a finding and aborts, so that libFuzzer
// (and the replay driver, through the abort) report it with the input: a crash or sanitizer
// report, a library's internal exception leaking out (nlohmann's json::exception names nothing
// the user wrote), std::bad_alloc (an input that implies unbounded memory), std::logic_error
// (a broken precondition inside trellis), or an exception with an empty message.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstdlib>
#include <new>
#include <stdexcept>
#include <string>

namespace trellis::fuzz {

[[noreturn]] inline void finding(const char* kind, const char* what) {
  std::fprintf(stderr, "fuzz finding: %s: %s\n", kind, what);
  std::abort();
}

/// Runs `body`; returns true if it finished, false if it rejected the input properly.
template <class Body>
bool rejectsCleanly(Body&& body) {
  try {
    body();
    return true;
  } catch (const nlohmann::json::exception& e) {
    finding("the JSON library's exception escaped", e.what());
  } catch (const std::bad_alloc&) {
    finding("std::bad_alloc", "the input implies unbounded memory");
  } catch (const std::logic_error& e) {
    finding("std::logic_error", e.what());
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).empty()) finding("an error without a message", "");
    return false;
  } catch (const std::exception& e) {
    finding("an unexpected exception", e.what());
  }
}

}  // namespace trellis::fuzz
