# cmake -P script behind the package.downstream test; see CMakeLists.txt beside it.
# Inputs: TRELLIS_BUILD_DIR, DOWNSTREAM_SOURCE_DIR, WORK_DIR, CONFIG, GENERATOR, CXX_COMPILER,
# CXX_FLAGS, EXE_LINKER_FLAGS.
cmake_minimum_required(VERSION 3.25)

set(prefix "${WORK_DIR}/prefix")
set(build "${WORK_DIR}/build")
file(REMOVE_RECURSE "${prefix}" "${build}")  # no stale files from an earlier run

if(NOT CONFIG)
  set(CONFIG Release)
endif()

function(run)
  message(STATUS "package.downstream: ${ARGV}")
  execute_process(COMMAND ${ARGV} COMMAND_ECHO NONE RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "package.downstream: failed (${rc}): ${ARGV}")
  endif()
endfunction()

# (a) install
run("${CMAKE_COMMAND}" --install "${TRELLIS_BUILD_DIR}" --prefix "${prefix}" --config "${CONFIG}")
foreach(f
    "include/trellis/core.hpp"
    "include/trellis/core/linearization.hpp")
  if(NOT EXISTS "${prefix}/${f}")
    message(FATAL_ERROR "package.downstream: ${f} was not installed")
  endif()
endforeach()

# (b) configure, build and run the downstream project against the prefix only
run("${CMAKE_COMMAND}" -S "${DOWNSTREAM_SOURCE_DIR}" -B "${build}" -G "${GENERATOR}"
  "-DCMAKE_PREFIX_PATH=${prefix}"
  "-DCMAKE_FIND_PACKAGE_NO_PACKAGE_REGISTRY=ON"
  "-DCMAKE_BUILD_TYPE=${CONFIG}"
  "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}"
  "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}"
  "-DCMAKE_EXE_LINKER_FLAGS=${EXE_LINKER_FLAGS}")
run("${CMAKE_COMMAND}" --build "${build}" --config "${CONFIG}")

set(app "${build}/app")
if(EXISTS "${build}/${CONFIG}/app")  # multi-config generators
  set(app "${build}/${CONFIG}/app")
endif()
run("${app}")
message(STATUS "package.downstream: ok")
