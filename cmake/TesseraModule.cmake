# One function for every module of src/ (docs/architecture.md, "Module map"):
#
#   tessera_add_module(NAME SOURCES a.cpp ... [DEPENDS tessera_x ...] [PUBLIC_LIBS ...]
#                      [PRIVATE_LIBS ...] [FOLDER dir])
#
# makes the static library tessera_NAME (alias tessera::NAME) from the sources in FOLDER
# (default: the calling CMakeLists.txt's folder) with three include roots:
#   - include/ at the repository root: the public API, PUBLIC and installed;
#   - FOLDER/include, when it exists: the module's interface to the other modules, PUBLIC to
#     them in the build tree only (never installed), included as "NAME/header.h";
#   - FOLDER itself: the module's private headers, PRIVATE, so that no other module can
#     include them (tests/boundaries proves a planted violation fails to compile).
# DEPENDS lists the Tessera modules this one may use; their interfaces come with them.
function(tessera_add_module name)
  cmake_parse_arguments(ARG "" "FOLDER" "SOURCES;DEPENDS;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
  if(NOT ARG_FOLDER)
    set(ARG_FOLDER ${CMAKE_CURRENT_SOURCE_DIR})
  endif()
  set(target tessera_${name})
  add_library(${target} STATIC ${ARG_SOURCES})
  add_library(tessera::${name} ALIAS ${target})
  target_include_directories(${target}
    PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
           $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>
    PRIVATE ${ARG_FOLDER})
  if(EXISTS ${ARG_FOLDER}/include)
    target_include_directories(${target} PUBLIC $<BUILD_INTERFACE:${ARG_FOLDER}/include>)
  endif()
  target_link_libraries(${target}
    PUBLIC ${ARG_DEPENDS} ${ARG_PUBLIC_LIBS}
    PRIVATE $<BUILD_INTERFACE:tessera_flags> ${ARG_PRIVATE_LIBS})
  set_property(TARGET ${target} PROPERTY TESSERA_PRIVATE_ROOT ${ARG_FOLDER})
  set_property(GLOBAL APPEND PROPERTY TESSERA_MODULES ${target})
endfunction()

# tessera_use_internals(TARGET MODULE...): white-box access for tests, benchmarks and fuzzers
# (never for a module): TARGET may include MODULE's private headers as "header.h".
function(tessera_use_internals target)
  foreach(module ${ARGN})
    get_property(root TARGET tessera_${module} PROPERTY TESSERA_PRIVATE_ROOT)
    target_include_directories(${target} PRIVATE ${root})
  endforeach()
endfunction()

# The Tessera modules `target` links, directly or through others.
function(tessera_linked_modules target out)
  set(seen "")
  set(queue ${target})
  while(queue)
    list(POP_FRONT queue current)
    get_target_property(links ${current} LINK_LIBRARIES)
    get_target_property(interface_links ${current} INTERFACE_LINK_LIBRARIES)
    foreach(link IN LISTS links interface_links)
      if(link MATCHES "^tessera_[a-z]+$" AND TARGET ${link} AND NOT link IN_LIST seen)
        list(APPEND seen ${link})
        list(APPEND queue ${link})
      endif()
    endforeach()
  endwhile()
  set(${out} ${seen} PARENT_SCOPE)
endfunction()

# tessera_forbid_links(TARGET FORBIDDEN...): configuration fails when TARGET reaches one of
# FORBIDDEN through its links, naming the rule (docs/architecture.md, "Rules at the seams").
function(tessera_forbid_links target)
  tessera_linked_modules(${target} linked)
  foreach(forbidden ${ARGN})
    if(forbidden IN_LIST linked)
      message(FATAL_ERROR "${target} links ${forbidden}: the runtime never links encoders or the "
                          "builder (docs/architecture.md, \"Rules at the seams\")")
    endif()
  endforeach()
endfunction()
