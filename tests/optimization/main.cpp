// Catch2's main() for trellis_optimization_tests.
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
