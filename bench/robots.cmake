# bench/robots.cmake — trellis_bench_robots: the URDF robots of ../shared/robots and the
# arbitrary-axis joint against const_se3 sandwiches (robots_bench.cpp).
if(NOT DEFINED TRELLIS_SHARED_DIR)
  get_filename_component(TRELLIS_SHARED_DIR "${CMAKE_CURRENT_SOURCE_DIR}/../../shared" ABSOLUTE)
endif()
add_executable(trellis_bench_robots robots_bench.cpp)
target_link_libraries(trellis_bench_robots PRIVATE trellis_bench_support benchmark::benchmark)
target_compile_definitions(trellis_bench_robots PRIVATE TRELLIS_SHARED_DIR="${TRELLIS_SHARED_DIR}")
