// Catch2's main() for trellis_analysis_tests.
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
