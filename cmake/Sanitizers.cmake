# ThreadSanitizer (SCALED_TSAN, preset tsan) and the fuzzing build (SCALED_FUZZ,
# preset fuzz). AddressSanitizer + UBSan alone (SCALED_SANITIZE, preset asan)
# is set up in the top-level CMakeLists.txt. One sanitizer family per build.
# docs/fuzzing.md says how each is run.

if((SCALED_TSAN AND SCALED_SANITIZE) OR (SCALED_TSAN AND SCALED_FUZZ)
   OR (SCALED_FUZZ AND SCALED_SANITIZE))
  message(FATAL_ERROR "SCALED_TSAN, SCALED_FUZZ and SCALED_SANITIZE exclude each other "
    "(ThreadSanitizer cannot be combined with AddressSanitizer; SCALED_FUZZ has its own ASan)")
endif()

if(SCALED_TSAN)
  add_compile_options(-fsanitize=thread -fno-omit-frame-pointer)
  add_link_options(-fsanitize=thread)
  # GCC 12: -Wtsan says std::atomic_thread_fence is not instrumented (the
  # code under test uses none directly, libstdc++'s headers may), and
  # -Wnull-dereference, perturbed by the instrumentation, gives a false
  # positive in libstdc++'s vector<string> relocation inlined from CLI11's
  # split() (CLI/StringTools.hpp). Both stay on in every other build. (On
  # scaled_warnings, after its -Wnull-dereference: the last option wins.)
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    target_compile_options(scaled_warnings INTERFACE -Wno-tsan -Wno-null-dereference)
  endif()
endif()

if(SCALED_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "SCALED_FUZZ needs clang (libFuzzer): configure with the fuzz preset "
      "or -DCMAKE_CXX_COMPILER=clang++ (Debian packages clang, libclang-rt-dev)")
  endif()
  # Every library the fuzz targets link: coverage for libFuzzer without its
  # main(), ASan and UBSan, stop at the first report. The targets themselves add
  # -fsanitize=fuzzer (tests/fuzz/CMakeLists.txt).
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=all)
  add_link_options(-fsanitize=address,undefined)
endif()
