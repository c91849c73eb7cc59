# bench/optimization.cmake — trellis_bench_optimization: Ipopt solve time and iterations against
# the number of knots for the cart-pole and acrobot swing-ups, exact vs finite-difference Jacobian;
# exact Hessian vs L-BFGS on the example problems and the swing-ups (family swingup).
if(TARGET trellis_optimization)
  add_executable(trellis_bench_optimization "${CMAKE_CURRENT_LIST_DIR}/optimization_bench.cpp")
  target_link_libraries(trellis_bench_optimization PRIVATE trellis::optimization benchmark::benchmark)
  target_compile_definitions(trellis_bench_optimization PRIVATE
    TRELLIS_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()
