# ctest: rebuilds the warning probe (tests/toolchain/warning_probe.cc) and checks that
# its deliberate warning is an error exactly when the build is strict.
#   cmake -DBUILD_DIR=... -DOBJECTS=... -DSTRICT=ON|OFF -P RunWarningProbe.cmake
file(REMOVE ${OBJECTS})
execute_process(
  COMMAND ${CMAKE_COMMAND} --build ${BUILD_DIR} --target build_warning_probe
  RESULT_VARIABLE result OUTPUT_VARIABLE output ERROR_VARIABLE output)
message("${output}")
if(STRICT)
  if(result EQUAL 0 OR NOT output MATCHES "error: unused variable")
    message(FATAL_ERROR "the strict build accepted a deliberate warning (exit ${result})")
  endif()
else()
  if(NOT result EQUAL 0)
    message(FATAL_ERROR "a non-strict build failed on a warning (exit ${result})")
  endif()
  if(NOT output MATCHES "warning: unused variable")
    message(FATAL_ERROR "the deliberate warning was not reported: the probe did not build")
  endif()
endif()
