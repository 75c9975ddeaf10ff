# Per-target include roots: no target exports the repository root, so a target
# sees only the folders of the libraries it links. A library exports a directory in the
# build tree that holds its own source folder, by symbolic link, under the folder's path in
# the repository: build/include/core/core/problem.h is core/problem.h. `#include
# "core/problem.h"` therefore compiles in the targets that link nupmpc_core and nowhere
# else. tests/build/layering_check.py checks the rules of ../shared/docs/architecture.md
# on the sources as well.
#
#   nupmpc_include_root(<target> <folder> [PRIVATE] [EXCLUDE <subfolder>...])
#
# EXCLUDE leaves subfolders out of the root (they are libraries of their own, e.g. core/gp
# and core/examples are not part of nupmpc_core's root). Roots are made at configure time;
# a new file at the top of a folder with EXCLUDE re-runs the configuration (CONFIGURE_DEPENDS).
function(nupmpc_include_root target folder)
  cmake_parse_arguments(R "PRIVATE" "" "EXCLUDE" ${ARGN})
  string(REPLACE "/" "_" id "${folder}")
  set(root "${PROJECT_BINARY_DIR}/include/${id}")
  get_property(made GLOBAL PROPERTY "nupmpc_include_root_${id}")
  if(NOT made)
    set(source "${PROJECT_SOURCE_DIR}/${folder}")
    file(REMOVE_RECURSE "${root}")
    if(R_EXCLUDE)
      file(MAKE_DIRECTORY "${root}/${folder}")
      file(GLOB entries CONFIGURE_DEPENDS LIST_DIRECTORIES true RELATIVE "${source}" "${source}/*")
      foreach(entry IN LISTS entries)
        if(NOT entry IN_LIST R_EXCLUDE AND NOT entry STREQUAL "CMakeLists.txt")
          file(CREATE_LINK "${source}/${entry}" "${root}/${folder}/${entry}" SYMBOLIC)
        endif()
      endforeach()
    else()
      get_filename_component(parent "${root}/${folder}" DIRECTORY)
      file(MAKE_DIRECTORY "${parent}")
      file(CREATE_LINK "${source}" "${root}/${folder}" SYMBOLIC)
    endif()
    set_property(GLOBAL PROPERTY "nupmpc_include_root_${id}" TRUE)
  endif()
  get_target_property(type ${target} TYPE)
  if(R_PRIVATE)
    set(scope PRIVATE)
  elseif(type STREQUAL "INTERFACE_LIBRARY")
    set(scope INTERFACE)
  else()
    set(scope PUBLIC)
  endif()
  target_include_directories(${target} ${scope} "${root}")
endfunction()
