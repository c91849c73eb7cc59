# bench/riccati.cmake — the Riccati benchmark (included by bench/CMakeLists.txt). Needs
# trellis::control, so it is skipped when bench/ is configured on its own (core only).
if(TARGET trellis_control)
  add_executable(trellis_bench_riccati ${CMAKE_CURRENT_LIST_DIR}/riccati_bench.cpp)
  target_link_libraries(trellis_bench_riccati PRIVATE trellis::control trellis_bench_support
                                                      benchmark::benchmark)
endif()
