# The install_consumer test (tests/CMakeLists.txt): installs the library from the build folder
# into a scratch prefix (cmake --install, component digitize), checks that the installed public
# headers include nothing but the standard library, Eigen and each other (docs/architecture.md),
# then configures, builds and runs tests/consumer/ against that prefix with find_package(digitize).
#
# cmake -DBUILD_DIR= -DSOURCE_DIR= -DWORK_DIR= -DGENERATOR= -DCXX= -DBUILD_TYPE= [-DLAUNCHER=]
#       [-DCXX_FLAGS=] -P run_consumer.cmake
cmake_minimum_required(VERSION 3.25)
foreach(var BUILD_DIR SOURCE_DIR WORK_DIR GENERATOR CXX BUILD_TYPE)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "run_consumer.cmake: -D${var}= missing")
  endif()
endforeach()

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}")
  endif()
  message(STATUS "${what}: ok")
  set(output "${out}" PARENT_SCOPE)
endfunction()

set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
run("install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --component digitize --prefix ${prefix})

file(GLOB headers ${prefix}/include/digitize/*.h)
if(NOT headers)
  message(FATAL_ERROR "nothing installed under ${prefix}/include/digitize")
endif()
foreach(header ${headers})
  file(STRINGS ${header} includes REGEX "^[ \t]*#[ \t]*include")
  foreach(line ${includes})
    # <vector>, <Eigen/Core>, "digitize/core.h"
    if(NOT line MATCHES "^[ \t]*#[ \t]*include[ \t]*(<[a-z_0-9]+>|<Eigen/[A-Za-z]+>|\"digitize/[a-z_0-9]+\\.h\")")
      message(FATAL_ERROR "${header}: '${line}': an installed header may include the standard "
                          "library, Eigen and digitize/ only (docs/architecture.md)")
    endif()
  endforeach()
endforeach()
list(LENGTH headers count)
message(STATUS "${count} installed headers include the standard library, Eigen and digitize/ only")

set(configure_args -S ${SOURCE_DIR} -B ${WORK_DIR}/build -G ${GENERATOR}
    -DCMAKE_CXX_COMPILER=${CXX} -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_PREFIX_PATH=${prefix})
if(LAUNCHER)
  list(APPEND configure_args -DCMAKE_CXX_COMPILER_LAUNCHER=${LAUNCHER})
endif()
if(CXX_FLAGS)  # a sanitizer build: the installed libraries need the same runtime
  list(APPEND configure_args "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}" "-DCMAKE_EXE_LINKER_FLAGS=${CXX_FLAGS}")
endif()
run("configure the consumer" ${CMAKE_COMMAND} ${configure_args})
run("build the consumer" ${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run("run the consumer" ${WORK_DIR}/build/digitize_consumer)
message(STATUS "${output}")
