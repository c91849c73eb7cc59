# Runs `trellis view ARGS --out OUT` and checks its exit status, its standard error and whether the page exists.
#
#   cmake -DTRELLIS=<exe> -DARGS="a|b" -DOUT=<page> -DEXPECT_EXIT=N [-DSTDERR_REGEX=..]
#         [-DEXPECT_FILE=ON|OFF] -P run_view.cmake
#
# The page is removed first, so that EXPECT_FILE=OFF checks that a failing run leaves none behind.
cmake_minimum_required(VERSION 3.25)
string(REPLACE "|" ";" ARGS "${ARGS}")
file(REMOVE "${OUT}")
get_filename_component(_dir "${OUT}" DIRECTORY)
file(MAKE_DIRECTORY "${_dir}")
execute_process(COMMAND "${TRELLIS}" view ${ARGS} --out "${OUT}" INPUT_FILE /dev/null
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
set(context "trellis view ${ARGS} --out ${OUT}\n  exit status: ${rc}\n  stdout: ${out}\n  stderr: ${err}")
if(NOT rc STREQUAL "${EXPECT_EXIT}")
  message(FATAL_ERROR "expected exit status ${EXPECT_EXIT}\n${context}")
endif()
if(DEFINED STDERR_REGEX AND NOT err MATCHES "${STDERR_REGEX}")
  message(FATAL_ERROR "stderr does not match '${STDERR_REGEX}'\n${context}")
endif()
if(EXPECT_FILE AND NOT EXISTS "${OUT}")
  message(FATAL_ERROR "no page written\n${context}")
endif()
if(NOT EXPECT_FILE)
  if(EXISTS "${OUT}")
    message(FATAL_ERROR "a failing run left a page behind\n${context}")
  endif()
  file(GLOB _left "${_dir}/*")
  if(_left)
    message(FATAL_ERROR "a failing run left files behind: ${_left}\n${context}")
  endif()
endif()
