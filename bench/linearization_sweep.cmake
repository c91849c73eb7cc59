# bench/linearization_sweep.cmake — trellis_bench_linearization_sweep: linearization time against
# the number of bodies and error against time, exact vs central and forward finite differences
# (the data of docs/performance.md, plots 1 and 2; see scripts/perf_report.sh).
add_executable(trellis_bench_linearization_sweep "${CMAKE_CURRENT_LIST_DIR}/linearization_sweep.cpp")
target_link_libraries(trellis_bench_linearization_sweep PRIVATE trellis_bench_support benchmark::benchmark)
