# scaled_add_driver(NAME SOURCES file... [PUBLIC dep...] [PRIVATE dep...])
#
# One driver subsystem (drivers/<folder>, docs/architecture.md): the static
# library scaled_NAME and its alias scaled::NAME, its public headers in the
# folder's include/ (scaled/drivers/<subsystem>/...), C++20, the project's
# warnings, and the given dependencies.
function(scaled_add_driver name)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "" "SOURCES;PUBLIC;PRIVATE")
  if(arg_UNPARSED_ARGUMENTS OR NOT arg_SOURCES)
    message(FATAL_ERROR "scaled_add_driver(${name}): SOURCES required; unknown: ${arg_UNPARSED_ARGUMENTS}")
  endif()
  add_library(scaled_${name} ${arg_SOURCES})
  add_library(scaled::${name} ALIAS scaled_${name})
  target_include_directories(scaled_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_compile_features(scaled_${name} PUBLIC cxx_std_20)
  target_link_libraries(scaled_${name} PUBLIC ${arg_PUBLIC} PRIVATE ${arg_PRIVATE} scaled_warnings)
endfunction()
