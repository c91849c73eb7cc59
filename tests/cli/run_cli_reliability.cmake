# Runs one `trellis` command on hostile input and checks that it fails cleanly: exit status,
# message, nothing on stdout, and no partial or temporary file left behind.
#
#   cmake -DTRELLIS=<exe> -DWORK=<dir> -DARGS="a|b" [-DEXPECT_EXIT=N] [-DSTDERR_REGEX=..]
#         [-DSTDOUT_REGEX=..] [-DSTDOUT_EMPTY=ON] [-DSTDERR_ONE_LINE=ON]
#         [-DULIMIT_F=<blocks>]      run under `ulimit -f` (a file-size limit)
#         [-DREAD_ONLY_DIR=<name>]   make WORK/<name> read-only first (skipped as root, who
#                                    writes anyway: the test prints SKIPPED)
#         [-DGENERATE=chain:N|flat:N]  write WORK/generated.json: a chain of N revolute frames,
#                                    or N revolute frames side by side
#         [-DWORK_FILES=a;b]         the only files WORK may hold afterwards (default: none)
#         [-DCHECK_DEV_FULL=ON]      /dev/full must still be a character device
#         -P run_cli_reliability.cmake
# "@WORK@" in ARGS stands for WORK, made empty for the test.
cmake_minimum_required(VERSION 3.25)

file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")

if(DEFINED GENERATE)
  string(REPLACE ":" ";" spec "${GENERATE}")
  list(GET spec 0 shape)
  list(GET spec 1 count)
  set(frames "")
  if(shape STREQUAL "chain")
    set(closing "")
    foreach(i RANGE 1 ${count})
      string(APPEND frames "{\"name\": \"l${i}\", \"type\": \"rz\", \"config\": \"q${i}\", \"mass\": {\"m\": 1}, \"children\": [")
      string(APPEND closing "]}")
    endforeach()
    string(APPEND frames "${closing}")
  else()
    foreach(i RANGE 1 ${count})
      if(i GREATER 1)
        string(APPEND frames ", ")
      endif()
      string(APPEND frames "{\"name\": \"l${i}\", \"type\": \"tx\", \"config\": \"q${i}\", \"mass\": {\"m\": 1}}")
    endforeach()
  endif()
  file(WRITE "${WORK}/generated.json" "{\"frames\": [${frames}]}\n")
  list(APPEND WORK_FILES generated.json)
endif()

if(DEFINED READ_ONLY_DIR)
  execute_process(COMMAND id -u OUTPUT_VARIABLE uid OUTPUT_STRIP_TRAILING_WHITESPACE)
  if(uid STREQUAL "0")
    message("SKIPPED: running as root, who can write into a read-only directory")
    return()
  endif()
  file(MAKE_DIRECTORY "${WORK}/${READ_ONLY_DIR}")
  file(CHMOD "${WORK}/${READ_ONLY_DIR}" DIRECTORY_PERMISSIONS OWNER_READ OWNER_EXECUTE)
endif()

string(REPLACE "@WORK@" "${WORK}" args "${ARGS}")
string(REPLACE "|" ";" args "${args}")
set(command "${TRELLIS}" ${args})
if(DEFINED ULIMIT_F)
  # sh's ulimit -f counts 512-byte blocks (dash) or 1024-byte blocks (bash); either is far below
  # the output of the commands tested with it.
  set(command sh -c "ulimit -f ${ULIMIT_F} && exec \"$0\" \"$@\"" ${command})
endif()
execute_process(COMMAND ${command} INPUT_FILE /dev/null
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(DEFINED READ_ONLY_DIR)
  file(CHMOD "${WORK}/${READ_ONLY_DIR}" DIRECTORY_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
endif()
set(context "${command}\n  exit status: ${rc}\n  stdout: ${out}\n  stderr: ${err}")

if(NOT DEFINED EXPECT_EXIT)
  set(EXPECT_EXIT 1)
endif()
if(NOT rc STREQUAL "${EXPECT_EXIT}")
  message(FATAL_ERROR "expected exit status ${EXPECT_EXIT} (a failure reported, not a crash)\n${context}")
endif()
if(DEFINED STDERR_REGEX AND NOT err MATCHES "${STDERR_REGEX}")
  message(FATAL_ERROR "stderr does not match '${STDERR_REGEX}'\n${context}")
endif()
if(DEFINED STDOUT_REGEX AND NOT out MATCHES "${STDOUT_REGEX}")
  message(FATAL_ERROR "stdout does not match '${STDOUT_REGEX}'\n${context}")
endif()
if(STDOUT_EMPTY AND NOT out STREQUAL "")
  message(FATAL_ERROR "expected nothing on stdout\n${context}")
endif()
if(STDERR_ONE_LINE AND NOT err MATCHES "^trellis: error: [^\n]+\n$")
  message(FATAL_ERROR "expected exactly one line 'trellis: error: ...' on stderr\n${context}")
endif()

# No partial output and no temporary (".NAME.tmp-XXXXXX") left: WORK holds only the inputs.
file(GLOB_RECURSE left RELATIVE "${WORK}" "${WORK}/*" "${WORK}/.*")
list(REMOVE_DUPLICATES left)
foreach(name IN LISTS left)
  if(NOT name IN_LIST WORK_FILES)
    message(FATAL_ERROR "the command left '${name}' in ${WORK}\n${context}")
  endif()
endforeach()
if(CHECK_DEV_FULL)
  execute_process(COMMAND test -c /dev/full RESULT_VARIABLE notDevice)
  if(NOT notDevice EQUAL 0)
    message(FATAL_ERROR "/dev/full is no longer a character device\n${context}")
  endif()
endif()
