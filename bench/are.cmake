# bench/are.cmake — CARE/DARE time against n beside the stabilizability screen (included by
# bench/CMakeLists.txt). Needs trellis::control, so it is skipped when bench/ is configured alone.
if(TARGET trellis_control)
  add_executable(trellis_bench_are ${CMAKE_CURRENT_LIST_DIR}/are_bench.cpp)
  target_link_libraries(trellis_bench_are PRIVATE trellis::control benchmark::benchmark)
endif()
