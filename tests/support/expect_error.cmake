# Runs tsah with ARGS (separated by @@) and checks the promise for bad input: exit status
# EXPECT_CODE, exactly one line on stderr starting with "tsah: " and matching EXPECT.
# Used by tests/cli/hardening*.cmake through tsah_expect_error().
string(REPLACE "@@" ";" args "${ARGS}")
execute_process(COMMAND ${TSAH} ${args} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err
                TIMEOUT 60 WORKING_DIRECTORY "${WORKDIR}")
if(NOT "${rc}" STREQUAL "${EXPECT_CODE}")
  message(FATAL_ERROR "exit status '${rc}', expected ${EXPECT_CODE}; stderr:\n${err}")
endif()
string(REGEX MATCHALL "\n" newlines "${err}")
list(LENGTH newlines lines)
if(NOT lines EQUAL 1 OR NOT err MATCHES "^tsah: [^\n]*\n$")
  message(FATAL_ERROR "stderr is not one 'tsah: ' line:\n${err}")
endif()
if(NOT err MATCHES "${EXPECT}")
  message(FATAL_ERROR "stderr does not match '${EXPECT}':\n${err}")
endif()
message(STATUS "ok: ${err}")
