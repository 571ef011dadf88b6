# ctest script: builds and runs tests/consumer against the package installed in
# PREFIX. Variables: SOURCE_DIR, WORK_DIR, PREFIX, NATIVE (ON/OFF), SANITIZE (ON/OFF:
# the installed libraries are instrumented, so the consumer links the runtimes).
file(REMOVE_RECURSE ${WORK_DIR})
set(extra_flags "")
if(SANITIZE)
  set(extra_flags "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined")
endif()
execute_process(
  COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR}/tests/consumer -B ${WORK_DIR}
          -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${PREFIX} -DCONSUMER_NATIVE=${NATIVE}
          ${extra_flags}
  RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer: configure failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer: build failed")
endif()
execute_process(COMMAND ${WORK_DIR}/consumer RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer: run failed")
endif()
