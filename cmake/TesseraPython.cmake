# Decides whether to build the Python extension (src/python) and finds what it needs:
# TESSERA_BUILD_PYTHON AUTO builds it when pybind11 (Debian: pybind11-dev) and the Python
# headers are found, no sanitizer is set and Tessera is the top-level project (not an
# add_subdirectory dependency); ON requires them; OFF skips it. Sets
# TESSERA_PYTHON_ENABLED and, when on, Python_EXECUTABLE (the interpreter the tests run).
#
# Debian's /usr/bin/python3 is preferred over whatever `python3` is first on PATH (a pyenv shim,
# say): it is the interpreter whose numpy and pytest the Debian packages install.
set(TESSERA_PYTHON_ENABLED OFF)
if(TESSERA_BUILD_PYTHON STREQUAL "OFF")
  return()
endif()
if(NOT TESSERA_BUILD_PYTHON STREQUAL "ON" AND (TESSERA_SANITIZE OR NOT PROJECT_IS_TOP_LEVEL))
  return()
endif()
if(NOT DEFINED Python_EXECUTABLE AND EXISTS /usr/bin/python3)
  set(Python_EXECUTABLE /usr/bin/python3 CACHE FILEPATH "The Python the extension is built for")
endif()
if(TESSERA_BUILD_PYTHON STREQUAL "ON")
  set(tessera_python_required REQUIRED)
endif()
find_package(Python 3.9 COMPONENTS Interpreter Development.Module ${tessera_python_required})
if(Python_FOUND)
  find_package(pybind11 2.10 CONFIG ${tessera_python_required})
endif()
if(NOT Python_FOUND OR NOT pybind11_FOUND)
  message(STATUS "Python module: off (needs pybind11-dev and python3-dev; see docs/python.md)")
  return()
endif()
set(TESSERA_PYTHON_ENABLED ON)
message(STATUS "Python module: on, for ${Python_EXECUTABLE} (pybind11 ${pybind11_VERSION})")
add_subdirectory(src/python)
