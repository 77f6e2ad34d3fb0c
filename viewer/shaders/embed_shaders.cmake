# Turns the GLSL files of this folder into one C++ header, so that the viewer library carries its
# shaders and an installed viewer has no shader folder to find. Run at build time by
# viewer/CMakeLists.txt:
#   cmake -DSHADER_DIR=<this folder> -DOUTPUT=<header> -P embed_shaders.cmake
#
# Each program, NAME.vert or NAME.frag, becomes `inline constexpr Source kNameVertex` (or
# kNameFragment; snake_case names turn CamelCase): its complete text and the legend of its GLSL
# source-string numbers. A line `#include "FILE.glsl"` is replaced by FILE.glsl of this folder
# (included files include nothing themselves), framed by `#line` directives: the included file is
# source string 1, 2, ... in the order of inclusion and the program itself is 0, so a compile error
# "1:12(3)" means line 12 of the first included file. The renderer adds the legend to the message.
# (Mesa sometimes names string 0 for an error inside an included file; its line number holds.)

cmake_minimum_required(VERSION 3.25)  # script mode: the policies of the project

if(NOT SHADER_DIR OR NOT OUTPUT)
  message(FATAL_ERROR "embed_shaders.cmake: -DSHADER_DIR=<folder> -DOUTPUT=<header> are needed")
endif()

# The text of SHADER_DIR/name, which must end with a newline (so that a #line can follow it).
function(read_shader name out)
  if(NOT EXISTS "${SHADER_DIR}/${name}")
    message(FATAL_ERROR "${SHADER_DIR}/${name}: no such shader file")
  endif()
  file(READ "${SHADER_DIR}/${name}" text)
  string(LENGTH "${text}" length)
  if(length EQUAL 0)
    message(FATAL_ERROR "${SHADER_DIR}/${name}: empty")
  endif()
  math(EXPR last "${length} - 1")
  string(SUBSTRING "${text}" ${last} 1 end)
  if(NOT end STREQUAL "\n")
    message(FATAL_ERROR "${SHADER_DIR}/${name}: the last line has no newline")
  endif()
  # The generated header holds it in a raw string R"glsl(...)glsl".
  string(FIND "${text}" ")glsl\"" clash)
  if(NOT clash EQUAL -1)
    message(FATAL_ERROR "${SHADER_DIR}/${name}: contains )glsl\", which ends the C++ raw string")
  endif()
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# The program `name` with its #include lines resolved (out_text) and its source-string legend
# (out_files: "0 plane.frag, 1 painting_common.glsl, ...").
function(resolve_program name out_text out_files)
  read_shader(${name} rest)
  set(text "")
  set(files "0 ${name}")
  set(index 0)
  set(line 1)  # line number in the program of the first line of `rest`
  while(TRUE)
    # A directive starts a line: found after a newline put before `rest`, it starts at `at`.
    string(FIND "\n${rest}" "\n#include " at)
    if(at EQUAL -1)
      break()
    endif()
    string(SUBSTRING "${rest}" 0 ${at} head)
    string(SUBSTRING "${rest}" ${at} -1 rest)
    string(FIND "${rest}" "\n" eol)
    string(SUBSTRING "${rest}" 0 ${eol} directive)
    math(EXPR after "${eol} + 1")
    string(SUBSTRING "${rest}" ${after} -1 rest)
    if(NOT directive MATCHES "^#include \"([A-Za-z0-9_]+\\.glsl)\"[ \t\r]*$")
      message(FATAL_ERROR "${SHADER_DIR}/${name}: `${directive}`: only #include \"FILE.glsl\"")
    endif()
    set(included ${CMAKE_MATCH_1})
    read_shader(${included} body)
    string(FIND "\n${body}" "\n#include " nested)
    if(NOT nested EQUAL -1)
      message(FATAL_ERROR "${SHADER_DIR}/${included}: an included file includes nothing")
    endif()
    string(REGEX MATCHALL "\n" newlines "${head}")
    list(LENGTH newlines head_lines)
    math(EXPR line "${line} + ${head_lines} + 1")
    math(EXPR index "${index} + 1")
    # GLSL 3.30 and later: `#line L S` numbers the line after it L, in source string S.
    string(APPEND text "${head}#line 1 ${index}\n${body}#line ${line} 0\n")
    string(APPEND files ", ${index} ${included}")
  endwhile()
  string(APPEND text "${rest}")
  set(${out_text} "${text}" PARENT_SCOPE)
  set(${out_files} "${files}" PARENT_SCOPE)
endfunction()

file(GLOB programs RELATIVE "${SHADER_DIR}" "${SHADER_DIR}/*.vert" "${SHADER_DIR}/*.frag")
list(SORT programs)
set(header "// Generated from viewer/shaders/ by viewer/shaders/embed_shaders.cmake: edit those files.\n")
string(APPEND header "#pragma once\n\nnamespace digitize::viewer::shaders {\n\n")
string(APPEND header "struct Source {\n  const char* text;   // the whole program, includes resolved\n")
string(APPEND header "  const char* files;  // GLSL source-string numbers: \"0 plane.frag, 1 ...\"\n};\n")
foreach(program IN LISTS programs)
  string(REGEX MATCH "^([a-z0-9_]+)\\.(vert|frag)$" ok "${program}")
  if(NOT ok)
    message(FATAL_ERROR "${SHADER_DIR}/${program}: program names are snake_case")
  endif()
  set(stem ${CMAKE_MATCH_1})
  if(CMAKE_MATCH_2 STREQUAL "vert")
    set(stage Vertex)
  else()
    set(stage Fragment)
  endif()
  string(REPLACE "_" ";" words "${stem}")
  set(identifier k)
  foreach(word IN LISTS words)
    string(SUBSTRING "${word}" 0 1 first)
    string(TOUPPER "${first}" first)
    string(SUBSTRING "${word}" 1 -1 others)
    string(APPEND identifier "${first}${others}")
  endforeach()
  string(APPEND identifier "${stage}")
  resolve_program(${program} text files)
  string(APPEND header "\n// ${program}\ninline constexpr Source ${identifier} = {R\"glsl(${text})glsl\",\n")
  string(APPEND header "    \"${files}\"};\n")
endforeach()
string(APPEND header "\n}  // namespace digitize::viewer::shaders\n")
file(WRITE "${OUTPUT}" "${header}")
