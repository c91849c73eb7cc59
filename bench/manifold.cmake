# bench/manifold.cmake — the manifold TV-LQR, the tangent-basis transport, controllability at the
# knots and the reachability Gramian along the hand's reference (examples/hand), and the Gramian of
# a damped planar chain (included by bench/CMakeLists.txt).
if(TARGET trellis_control AND TARGET trellis_hand_reference)
  add_executable(trellis_bench_manifold ${CMAKE_CURRENT_LIST_DIR}/manifold_bench.cpp)
  target_link_libraries(trellis_bench_manifold PRIVATE trellis::control trellis_hand_reference
                                                       trellis_bench_support benchmark::benchmark)
  target_compile_definitions(trellis_bench_manifold PRIVATE
    TRELLIS_EXAMPLE_SCENES_DIR="${PROJECT_SOURCE_DIR}/examples/scenes")
endif()
