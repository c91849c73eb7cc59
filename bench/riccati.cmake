# bench/riccati.cmake — the Riccati benchmark (included by bench/CMakeLists.txt). Needs
# trellis::control, so it is skipped when bench/ is configured on its own (core only).
if(TARGET trellis_control)
  add_executable(trellis_bench_riccati ${CMAKE_CURRENT_LIST_DIR}/riccati_bench.cpp)
  target_link_libraries(trellis_bench_riccati PRIVATE trellis::control trellis_bench_support
                                                      benchmark::benchmark)
  add_executable(trellis_bench_riccati_profile ${CMAKE_CURRENT_LIST_DIR}/riccati_profile.cpp)
  target_link_libraries(trellis_bench_riccati_profile PRIVATE trellis::control trellis_bench_support)
endif()

# Sampled-data (ZOH) TV-LQR along the hand's reference (needs the examples' hand reference).
if(TARGET trellis_control AND TARGET trellis_hand_reference)
  add_executable(trellis_bench_sampled ${CMAKE_CURRENT_LIST_DIR}/sampled_bench.cpp)
  target_link_libraries(trellis_bench_sampled PRIVATE trellis::control trellis_hand_reference)
  target_compile_definitions(trellis_bench_sampled PRIVATE
    TRELLIS_EXAMPLE_SCENES_DIR="${PROJECT_SOURCE_DIR}/examples/scenes")
endif()

# Sampled-data gains against the continuous gains on the 6-link hanging chain (issue 31).
if(TARGET trellis_control)
  add_executable(trellis_bench_sampled_gains ${CMAKE_CURRENT_LIST_DIR}/sampled_gains_bench.cpp)
  target_link_libraries(trellis_bench_sampled_gains PRIVATE trellis::control benchmark::benchmark)
endif()
