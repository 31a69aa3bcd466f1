# paps hands the image commands to paps-fusion: paps itself must not load OpenCV's image codecs
# (nor GDAL, which they pull in: about 140 shared libraries and half of every start-up), the
# commands must work through paps, and a paps without paps-fusion beside it must say so.
#   -DPAPS=<paps> -DWORK_DIR=<scratch>
execute_process(COMMAND ldd ${PAPS} RESULT_VARIABLE rc OUTPUT_VARIABLE libs ERROR_VARIABLE err)
if(NOT rc STREQUAL "0")
  message(FATAL_ERROR "ldd ${PAPS} failed: ${err}")
endif()
foreach(lib libopencv_imgcodecs libgdal)
  if(libs MATCHES "${lib}")
    message(FATAL_ERROR "paps loads ${lib}:\n${libs}")
  endif()
endforeach()

# Through paps: the command's own usage, and its own argument check.
execute_process(COMMAND ${PAPS} register --help RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc STREQUAL "0" OR NOT out MATCHES "usage: paps register CLOUD LIST OUT_LIST")
  message(FATAL_ERROR "paps register --help: ${rc}\n${out}\n${err}")
endif()
execute_process(COMMAND ${PAPS} --threads 1 colorize RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc STREQUAL "1" OR NOT err MATCHES "^paps: error: invalid parameter 'arguments'")
  message(FATAL_ERROR "paps colorize without arguments: ${rc}\n${out}\n${err}")
endif()

# paps alone in a folder: one clear line naming the missing binary, exit 1.
file(REMOVE_RECURSE ${WORK_DIR}/alone)
file(MAKE_DIRECTORY ${WORK_DIR}/alone)
file(COPY ${PAPS} DESTINATION ${WORK_DIR}/alone)
execute_process(COMMAND ${WORK_DIR}/alone/paps make-street ${WORK_DIR}/alone/street
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc STREQUAL "1" OR NOT err MATCHES "cannot run .*/alone/paps-fusion, which holds the 'make-street' command"
   OR EXISTS ${WORK_DIR}/alone/street)
  message(FATAL_ERROR "paps without paps-fusion: ${rc}\n${out}\n${err}")
endif()
