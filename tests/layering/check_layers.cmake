# The layering test (tests/CMakeLists.txt): every file of a library layer includes only headers of
# its own layer and of the layers it links (libdigitize/CMakeLists.txt; order and contents:
# docs/architecture.md), and every public header and .cpp of libdigitize/ belongs to one layer.
#
# cmake -DLAYERS=<build>/tests/layers.cmake -DLIB_DIR=<source>/libdigitize -P check_layers.cmake
# LAYERS sets DIGITIZE_LAYERS (the layer targets) and, per layer L, L_FILES (its headers and
# sources) and L_ALLOWED (the header names it may include).
cmake_minimum_required(VERSION 3.25)
include(${LAYERS})

# Layer breaks known and being fixed, as "file -> header"; remove a line when its fix lands.
set(known_breaks)

set(errors "")
set(owned "")
foreach(layer ${DIGITIZE_LAYERS})
  foreach(file ${${layer}_FILES})
    get_filename_component(name ${file} NAME)
    if(name IN_LIST owned)
      string(APPEND errors "  ${name} is listed in two layers\n")
    endif()
    list(APPEND owned ${name})
    file(STRINGS ${file} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"digitize/")
    foreach(line ${lines})
      string(REGEX REPLACE ".*\"digitize/([^\"]+)\".*" "\\1" header "${line}")
      if(NOT header IN_LIST ${layer}_ALLOWED AND NOT "${name} -> ${header}" IN_LIST known_breaks)
        string(APPEND errors "  ${name} (${layer}) includes digitize/${header}, a header of a "
                             "layer ${layer} does not link\n")
      endif()
    endforeach()
  endforeach()
endforeach()

file(GLOB all_files ${LIB_DIR}/include/digitize/*.h ${LIB_DIR}/src/*.cpp)
foreach(file ${all_files})
  get_filename_component(name ${file} NAME)
  if(NOT name IN_LIST owned)
    string(APPEND errors "  ${name} is in no layer: add it to its layer's HEADERS or SOURCES in "
                         "libdigitize/CMakeLists.txt\n")
  endif()
endforeach()

if(errors)
  message(FATAL_ERROR "layer rules broken (docs/architecture.md):\n${errors}")
endif()
list(LENGTH owned count)
message(STATUS "${count} files in ${DIGITIZE_LAYERS}: every include within its layer's reach")
