# bench/simulation.cmake — trellis_bench_simulation: one 3 s closed loop of the hand and the main
# job's batch of 20 (needs trellis::control and the examples' hand reference).
if(TARGET trellis_control AND TARGET trellis_hand_reference)
  add_executable(trellis_bench_simulation ${CMAKE_CURRENT_LIST_DIR}/simulation_bench.cpp)
  target_link_libraries(trellis_bench_simulation PRIVATE trellis::control trellis_hand_reference
                                                         benchmark::benchmark)
  target_compile_definitions(trellis_bench_simulation PRIVATE
    TRELLIS_EXAMPLE_SCENES_DIR="${PROJECT_SOURCE_DIR}/examples/scenes")
endif()
