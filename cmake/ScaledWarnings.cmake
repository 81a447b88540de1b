# scaled_warnings: an interface target every project target links, so warning
# policy lives in one place.
add_library(scaled_warnings INTERFACE)
target_compile_options(scaled_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wsign-conversion
  -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Woverloaded-virtual
  -Wnull-dereference -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)
if(SCALED_WERROR)
  target_compile_options(scaled_warnings INTERFACE -Werror)
endif()
# GCC 12 reports -Wrestrict false positives inside libstdc++'s std::string
# operator+ at -O2/-O3 (GCC bug 105329); the check stays on for other compilers.
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_GREATER_EQUAL 12
   AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
  target_compile_options(scaled_warnings INTERFACE -Wno-restrict)
endif()
