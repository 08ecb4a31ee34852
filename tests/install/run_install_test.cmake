# Install/export test, run by ctest as `cmake -P`: installs the build tree into a temporary
# prefix, checks that every public header and the package files are there, then configures,
# builds and runs tests/install as a separate project against that prefix only.
#
# Inputs (-D): TESSERA_SOURCE_DIR, TESSERA_BINARY_DIR, WORK_DIR, BUILD_TYPE, GENERATOR,
# CXX_COMPILER, SANITIZE (the main build's TESSERA_SANITIZE; the consumer must link the same
# runtime to link the instrumented static libraries).
cmake_minimum_required(VERSION 3.25)

foreach(var TESSERA_SOURCE_DIR TESSERA_BINARY_DIR WORK_DIR GENERATOR CXX_COMPILER)
  if(NOT ${var})
    message(FATAL_ERROR "install test: -D${var}=... is required")
  endif()
endforeach()
if(NOT BUILD_TYPE)
  set(BUILD_TYPE Release)
endif()

set(prefix ${WORK_DIR}/prefix)
set(consumer_build ${WORK_DIR}/consumer-build)
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})

function(run_step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "install test: ${what} failed (${rc}):\n${out}")
  endif()
  message(STATUS "install test: ${what}: ok")
endfunction()

run_step("cmake --install" ${CMAKE_COMMAND} --install ${TESSERA_BINARY_DIR} --prefix ${prefix}
         --config ${BUILD_TYPE})

# Every public header in the source tree must be installed.
file(GLOB source_headers RELATIVE ${TESSERA_SOURCE_DIR}/include
     ${TESSERA_SOURCE_DIR}/include/tessera/*.h)
foreach(header IN LISTS source_headers)
  if(NOT EXISTS ${prefix}/include/${header})
    message(FATAL_ERROR "install test: ${header} is not installed under ${prefix}/include")
  endif()
endforeach()

# The package files, wherever GNUInstallDirs put the libdir.
file(GLOB config LIST_DIRECTORIES false ${prefix}/lib*/cmake/Tessera/TesseraConfig.cmake)
file(GLOB config_version LIST_DIRECTORIES false
     ${prefix}/lib*/cmake/Tessera/TesseraConfigVersion.cmake)
file(GLOB targets LIST_DIRECTORIES false ${prefix}/lib*/cmake/Tessera/TesseraTargets.cmake)
if(NOT config OR NOT config_version OR NOT targets)
  message(FATAL_ERROR "install test: TesseraConfig.cmake, TesseraConfigVersion.cmake or "
                      "TesseraTargets.cmake missing under ${prefix}/lib*/cmake/Tessera")
endif()

set(sanitize_flags "")
if(SANITIZE)
  set(sanitize_flags "-fsanitize=${SANITIZE} -fno-omit-frame-pointer")
endif()
run_step("configure consumer"
         ${CMAKE_COMMAND} -S ${TESSERA_SOURCE_DIR}/tests/install -B ${consumer_build}
         -G ${GENERATOR} -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
         -DTESSERA_PREFIX=${prefix}
         -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF -DCMAKE_FIND_USE_SYSTEM_PACKAGE_REGISTRY=OFF
         "-DCMAKE_CXX_FLAGS=${sanitize_flags}" "-DCMAKE_EXE_LINKER_FLAGS=${sanitize_flags}")
run_step("build consumer" ${CMAKE_COMMAND} --build ${consumer_build} -j 2)
file(MAKE_DIRECTORY ${WORK_DIR}/run)
run_step("run consumer" ${consumer_build}/consumer ${WORK_DIR}/run)
