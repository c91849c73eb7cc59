# tests/cli/tests_funnel.cmake — `trellis funnel` and `trellis-mpi funnel` (issue 29): determinism
# across threads and MPI ranks, bad input, by the script funnel/funnel_mpi.sh in an empty work
# directory. Included by tests/cli/CMakeLists.txt.
set(_funnel_mpi "")
if(TARGET trellis-mpi)
  set(_funnel_mpi "$<TARGET_FILE:trellis-mpi>")
endif()
set(_funnel_work "${CMAKE_CURRENT_BINARY_DIR}/cli_work/funnel")
add_test(NAME cli.funnel.threads_ranks_and_errors
  COMMAND ${CMAKE_COMMAND} -E env "TRELLIS=$<TARGET_FILE:trellis>"
          "TRELLIS_MPI=${_funnel_mpi}" "SOURCE_DIR=${PROJECT_SOURCE_DIR}"
          sh -c "rm -rf '${_funnel_work}' && mkdir -p '${_funnel_work}' && cd '${_funnel_work}' && sh -eu '${CMAKE_CURRENT_LIST_DIR}/funnel/funnel_mpi.sh'")
set_tests_properties(cli.funnel.threads_ranks_and_errors PROPERTIES LABELS cli TIMEOUT 120)
