# Installs the PAPS build tree into a scratch prefix, then configures, builds and runs the
# consumer project against it. Invoked by CTest (test/CMakeLists.txt) with
#   -DPAPS_BINARY_DIR=<PAPS build tree> -DCONSUMER_SOURCE_DIR=<this folder> -DWORK_DIR=<scratch>
# Fails with FATAL_ERROR on any non-zero step.
foreach(var PAPS_BINARY_DIR CONSUMER_SOURCE_DIR WORK_DIR)
  if(NOT DEFINED ${var} OR "${${var}}" STREQUAL "")
    message(FATAL_ERROR "run_consumer.cmake: ${var} is not set")
  endif()
endforeach()

set(prefix ${WORK_DIR}/prefix)
set(build ${WORK_DIR}/build)
# Start clean so that a stale install or cache cannot hide a broken package.
file(REMOVE_RECURSE ${prefix} ${build})
file(MAKE_DIRECTORY ${build})

# Same build type as the tree being tested (single-config generators ignore --config).
set(config Release)
if(EXISTS ${PAPS_BINARY_DIR}/CMakeCache.txt)
  file(STRINGS ${PAPS_BINARY_DIR}/CMakeCache.txt bt REGEX "^CMAKE_BUILD_TYPE:")
  if(bt)
    string(REGEX REPLACE "^CMAKE_BUILD_TYPE:[A-Z]*=" "" bt "${bt}")
    if(NOT bt STREQUAL "")
      set(config ${bt})
    endif()
  endif()
endif()

function(run_step name)
  execute_process(COMMAND ${ARGN}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc STREQUAL "0")
    message(FATAL_ERROR "consumer: ${name} failed (${rc})\n--- command: ${ARGN}\n--- stdout:\n${out}\n--- stderr:\n${err}")
  endif()
  message(STATUS "consumer: ${name} ok")
  set(step_output "${out}" PARENT_SCOPE)
endfunction()

run_step(install ${CMAKE_COMMAND} --install ${PAPS_BINARY_DIR} --prefix ${prefix} --config ${config})
if(NOT EXISTS ${prefix}/lib/cmake/PAPS/PAPSConfig.cmake AND NOT EXISTS ${prefix}/lib64/cmake/PAPS/PAPSConfig.cmake)
  file(GLOB_RECURSE found ${prefix}/*PAPSConfig.cmake)
  if(NOT found)
    message(FATAL_ERROR "consumer: no PAPSConfig.cmake installed under ${prefix}")
  endif()
endif()

run_step(configure ${CMAKE_COMMAND} -S ${CONSUMER_SOURCE_DIR} -B ${build}
  -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=${config})
run_step(build ${CMAKE_COMMAND} --build ${build} --config ${config})

find_program(consumer_exe paps_consumer PATHS ${build} ${build}/${config} NO_DEFAULT_PATH)
if(NOT consumer_exe)
  message(FATAL_ERROR "consumer: built, but no paps_consumer executable in ${build}")
endif()
run_step(run ${consumer_exe})
message(STATUS "${step_output}")

# The examples of docs/examples, built on their own against the same installed package (as a
# user copies them): every one the configuration lists. They are run here when the tree does
# not build them (RUN_EXAMPLES, scripts/test.sh): each example is compiled and run once per
# test run, not twice (about 100 s of compile and 55 s of runs in CI).
if(DEFINED EXAMPLES_SOURCE_DIR AND NOT EXAMPLES_SOURCE_DIR STREQUAL "")
  set(examples_build ${WORK_DIR}/examples)
  file(REMOVE_RECURSE ${examples_build})
  file(MAKE_DIRECTORY ${examples_build})
  run_step(configure-examples ${CMAKE_COMMAND} -S ${EXAMPLES_SOURCE_DIR} -B ${examples_build}
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=${config})
  run_step(build-examples ${CMAKE_COMMAND} --build ${examples_build} --config ${config} --parallel 2)
  file(READ ${examples_build}/example_targets.txt listed)
  list(LENGTH listed listed_count)
  if(listed_count LESS 1)
    message(FATAL_ERROR "consumer: the examples' configuration listed no example")
  endif()
  foreach(name IN LISTS listed)
    find_program(exe_${name} ${name} PATHS ${examples_build} ${examples_build}/${config} NO_DEFAULT_PATH)
    if(NOT exe_${name})
      message(FATAL_ERROR "consumer: ${name} was not built in ${examples_build}")
    endif()
    if(RUN_EXAMPLES)
      # Without arguments each example checks its own result on a shape with a known answer.
      execute_process(COMMAND ${exe_${name}} WORKING_DIRECTORY ${examples_build}
        RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
      if(NOT rc STREQUAL "0")
        message(FATAL_ERROR "consumer: ${name} failed (${rc})\n${out}\n${err}")
      endif()
      message(STATUS "consumer: ${name} ran and checked its result")
    endif()
  endforeach()
  message(STATUS "consumer: ${listed_count} examples built")
endif()
