# tests/cli/tests_reliability3.cmake — issue 24 (reliability, third round): the command line's
# outputs, checks, URDF, names and readers, each a shell script of tests/cli/shell/ run in an empty
# work directory (run_cli_shell.cmake). Included by tests/cli/CMakeLists.txt.
file(GLOB _shell_scripts CONFIGURE_DEPENDS "${CMAKE_CURRENT_LIST_DIR}/shell/*.sh")
foreach(_script IN LISTS _shell_scripts)
  get_filename_component(_stem "${_script}" NAME_WE)
  if(_stem STREQUAL "common")
    continue()
  endif()
  add_test(NAME cli.reliability3.${_stem}
    COMMAND ${CMAKE_COMMAND} "-DTRELLIS=$<TARGET_FILE:trellis>" "-DSCRIPT=${_script}"
            "-DWORK=${CMAKE_CURRENT_BINARY_DIR}/cli_work/reliability3.${_stem}" "-DSOURCE_DIR=${PROJECT_SOURCE_DIR}"
            -P "${CMAKE_CURRENT_LIST_DIR}/run_cli_shell.cmake")
  set_tests_properties(cli.reliability3.${_stem} PROPERTIES LABELS cli SKIP_REGULAR_EXPRESSION "SKIPPED:")
endforeach()
