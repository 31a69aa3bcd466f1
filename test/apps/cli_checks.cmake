# Helpers shared by the CLI test scripts (run_cli.cmake, run_cli_transport.cmake, run_cli_fusion.cmake).

# Runs paps with the arguments; sets rc, out and err in the caller and logs the run.
function(run_paps)
  execute_process(COMMAND ${PAPS} ${ARGN}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(rc "${rc}" PARENT_SCOPE)
  set(out "${out}" PARENT_SCOPE)
  set(err "${err}" PARENT_SCOPE)
  message(STATUS "paps ${ARGN}\n  exit: ${rc}\n  stdout: ${out}\n  stderr: ${err}")
endfunction()

# The last run failed cleanly: a non-zero exit and exactly one line on stderr, starting with
# "paps: error:" and containing `mention`. (What it may leave behind each script checks.)
function(expect_error_line mention)
  if(rc STREQUAL "0")
    message(FATAL_ERROR "expected a non-zero exit, got 0")
  endif()
  if(NOT rc MATCHES "^[0-9]+$")
    message(FATAL_ERROR "paps did not exit normally: ${rc}")
  endif()
  string(REGEX REPLACE "\n$" "" line "${err}")
  if(line MATCHES "\n")
    message(FATAL_ERROR "expected one line on stderr, got:\n${err}")
  endif()
  if(NOT line MATCHES "^paps: error: ")
    message(FATAL_ERROR "stderr does not start with 'paps: error: ': ${err}")
  endif()
  string(FIND "${line}" "${mention}" at)
  if(at EQUAL -1)
    message(FATAL_ERROR "the error line does not mention '${mention}': ${line}")
  endif()
endfunction()

# A failed run in the case folder `dir`: expect_error_line, and nothing written (no out*
# output, no temporary file) beside the inputs.
function(expect_error mention)
  expect_error_line("${mention}")
  file(GLOB left LIST_DIRECTORIES false ${dir}/out* ${dir}/.out* ${dir}/*.tmp*)
  if(left)
    message(FATAL_ERROR "a failed run left files behind: ${left}")
  endif()
endfunction()
