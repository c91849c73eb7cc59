# bench/robots.cmake — trellis_bench_robots: the URDF robots of tests/data/robots and the
# arbitrary-axis joint against const_se3 sandwiches (robots_bench.cpp).
add_executable(trellis_bench_robots robots_bench.cpp)
target_link_libraries(trellis_bench_robots PRIVATE trellis_bench_support benchmark::benchmark)
target_compile_definitions(trellis_bench_robots PRIVATE
  TRELLIS_ROBOTS_DIR="${PROJECT_SOURCE_DIR}/tests/data/robots")
