# Runs one shell script of tests/cli/shell/ in an empty work directory. The script checks what a
# single command line cannot: a redirected stream (`>> log`), files before and after, a signal.
# It exits 0 when every check holds, 77 to skip (printed as SKIPPED), else prints why and fails.
#
#   cmake -DTRELLIS=<exe> -DSCRIPT=<file.sh> -DWORK=<dir> -DSOURCE_DIR=<repo> -P run_cli_shell.cmake
cmake_minimum_required(VERSION 3.25)
file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")
execute_process(COMMAND "${CMAKE_COMMAND}" -E env "TRELLIS=${TRELLIS}" "SOURCE_DIR=${SOURCE_DIR}" sh -eu "${SCRIPT}"
  WORKING_DIRECTORY "${WORK}"
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err
  INPUT_FILE /dev/null)
if(rc STREQUAL "77")
  message("SKIPPED: ${out}")
  return()
endif()
if(NOT rc STREQUAL "0")
  message(FATAL_ERROR "${SCRIPT} failed (exit status ${rc})\n  stdout: ${out}\n  stderr: ${err}")
endif()
file(REMOVE_RECURSE "${WORK}")
