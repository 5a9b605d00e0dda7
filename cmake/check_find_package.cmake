# Test driver (ctest example.find_package): install the built library into a scratch prefix and
# build examples/cpp as an outside project that only knows find_package(flagsim).
set(prefix ${FLAGSIM_BUILD_DIR}/find_package_check/prefix)
set(bdir ${FLAGSIM_BUILD_DIR}/find_package_check/build)
file(REMOVE_RECURSE ${prefix})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${FLAGSIM_BUILD_DIR} --component dev --prefix ${prefix}
                RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "install failed: ${rc}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${FLAGSIM_SOURCE_DIR}/examples/cpp -B ${bdir}
                -G ${CMAKE_GENERATOR} -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=Release
                RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "configure of the consumer project failed: ${rc}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${bdir} RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "build of the consumer project failed: ${rc}")
endif()
execute_process(COMMAND ${bdir}/minimal RESULT_VARIABLE rc OUTPUT_VARIABLE out)
message(STATUS "${out}")
if(rc)
  message(FATAL_ERROR "consumer example failed: ${rc}")
endif()
