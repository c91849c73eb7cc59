# bench/second_order.cmake — the exact second derivatives (issue 30): trellis_bench_second_order
# (Google Benchmark: contraction and tensors against n, error against central differences of the
# exact Jacobians, and the time of those differences) and trellis_bench_second_order_profile (a
# loop for callgrind instruction counts against one linearization).
add_executable(trellis_bench_second_order "${CMAKE_CURRENT_LIST_DIR}/second_order_bench.cpp")
target_link_libraries(trellis_bench_second_order PRIVATE trellis_bench_support benchmark::benchmark)
add_executable(trellis_bench_second_order_profile "${CMAKE_CURRENT_LIST_DIR}/second_order_profile.cpp")
target_link_libraries(trellis_bench_second_order_profile PRIVATE trellis_bench_support)
# contract_tape reaches the tape switch in core/src/second_order_tree.hpp.
target_include_directories(trellis_bench_second_order_profile PRIVATE "${CMAKE_CURRENT_LIST_DIR}/../core/src")
target_compile_definitions(trellis_bench_second_order PRIVATE
  TRELLIS_EXAMPLE_SCENES_DIR="${PROJECT_SOURCE_DIR}/examples/scenes")
