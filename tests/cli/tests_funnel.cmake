# tests/cli/tests_funnel.cmake — `trellis funnel` and `trellis-mpi funnel` (issue 29): determinism
# across threads and MPI ranks, bad input, by the script funnel/funnel_mpi.sh (two parts) in empty work
# directories. Included by tests/cli/CMakeLists.txt.
# trellis_funnel_test(NAME PART): the script's part in its own empty work directory.
function(trellis_funnel_test name part)
  set(_work "${CMAKE_CURRENT_BINARY_DIR}/cli_work/funnel_${part}")
  set(_mpi "")
  if(TARGET trellis-mpi)
    set(_mpi "$<TARGET_FILE:trellis-mpi>")
  endif()
  add_test(NAME cli.funnel.${name}
    COMMAND ${CMAKE_COMMAND} -E env "TRELLIS=$<TARGET_FILE:trellis>" "TRELLIS_MPI=${_mpi}"
            "SOURCE_DIR=${PROJECT_SOURCE_DIR}"
            sh -c "rm -rf '${_work}' && mkdir -p '${_work}' && cd '${_work}' && sh -eu '${CMAKE_CURRENT_LIST_DIR}/funnel/funnel_mpi.sh' ${part}")
  set_tests_properties(cli.funnel.${name} PROPERTIES LABELS cli TIMEOUT 120)
endfunction()
trellis_funnel_test(threads_and_errors threads)
# Registered only with trellis-mpi (MPI found at configure time); it then needs a working mpirun.
if(TARGET trellis-mpi)
  trellis_funnel_test(mpi_ranks_and_errors mpi)
endif()
