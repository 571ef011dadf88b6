# ctest script: configures, builds and runs a project outside diffdyn against the
# package installed in PREFIX. Variables: SOURCE_DIR (the project's folder), WORK_DIR,
# PREFIX, PROGRAM (the executable the project builds), RUN_ARGS (its arguments,
# space-separated, optional), NATIVE (ON/OFF, optional: passed as -DCONSUMER_NATIVE), SANITIZE (ON/OFF:
# the installed libraries are instrumented, so the project links the runtimes).
file(REMOVE_RECURSE ${WORK_DIR})
set(extra_flags "")
if(DEFINED NATIVE)
  list(APPEND extra_flags "-DCONSUMER_NATIVE=${NATIVE}")
endif()
if(SANITIZE)
  list(APPEND extra_flags "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined")
endif()
execute_process(
  COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR}
          -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${PREFIX} ${extra_flags}
  RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${PROGRAM}: configure failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${PROGRAM}: build failed")
endif()
separate_arguments(run_args UNIX_COMMAND "${RUN_ARGS}")
execute_process(COMMAND ${WORK_DIR}/${PROGRAM} ${run_args} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${PROGRAM}: run failed (exit ${rc})")
endif()
