# Cross-compiling for 64-bit ARM Linux (Raspberry Pi 4/5, Jetson) with Debian's
# g++-aarch64-linux-gnu; tests run under qemu-aarch64-static (docs/arm.md).
#
# Two ways to use it:
#   - without a sysroot (presets aarch64, aarch64-float): core and its tests
#     only (SCALED_CORE_ONLY=ON). The target's libc/libstdc++ come with the
#     cross compiler under /usr/aarch64-linux-gnu, Eigen is the host's
#     (header-only, the same on every architecture) and GoogleTest is built
#     from /usr/src/googletest (SCALED_GTEST_FROM_SOURCE=ON).
#   - with a sysroot (preset aarch64-sysroot, scripts/cross-build-arm64.sh): the
#     whole project against an arm64 Debian tree holding every -dev package
#     (scripts/make-arm64-sysroot.sh). Set SCALED_ARM64_SYSROOT (cache variable
#     or environment variable) to its directory.

set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

# Debian's cross compilers (package g++-aarch64-linux-gnu). The version-less
# names follow Debian's default GCC (12 on bookworm), like the host's g++.
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

# The sysroot: from the cache (-DSCALED_ARM64_SYSROOT=DIR, the preset), else the
# environment. try_compile projects read this file again with an empty cache,
# so the variable is forwarded to them.
if(NOT DEFINED SCALED_ARM64_SYSROOT AND DEFINED ENV{SCALED_ARM64_SYSROOT})
  set(SCALED_ARM64_SYSROOT "$ENV{SCALED_ARM64_SYSROOT}")
endif()
set(SCALED_ARM64_SYSROOT "${SCALED_ARM64_SYSROOT}" CACHE PATH
  "arm64 Debian sysroot for the whole-project cross build (empty: core only, no sysroot)")
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES SCALED_ARM64_SYSROOT)

# qemu-user runs the target's programs: gtest_discover_tests lists the tests
# through it at build time and ctest runs them through it. The program loader
# does not run anything per-user, so no binfmt_misc registration is needed.
find_program(SCALED_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64)

if(SCALED_ARM64_SYSROOT)
  if(NOT EXISTS "${SCALED_ARM64_SYSROOT}/usr/include/aarch64-linux-gnu")
    message(FATAL_ERROR "SCALED_ARM64_SYSROOT=${SCALED_ARM64_SYSROOT} is not an arm64 sysroot "
      "(no usr/include/aarch64-linux-gnu): make one with scripts/make-arm64-sysroot.sh DIR")
  endif()
  # --sysroot for compiling and linking; find_* look only inside it.
  set(CMAKE_SYSROOT "${SCALED_ARM64_SYSROOT}")
  set(CMAKE_FIND_ROOT_PATH "${SCALED_ARM64_SYSROOT}")
  # pkg_check_modules (libgpiod, libcamera, systemd dirs): the target's .pc files
  # only, and their -I/-L paths prefixed with the sysroot.
  set(ENV{PKG_CONFIG_SYSROOT_DIR} "${SCALED_ARM64_SYSROOT}")
  set(ENV{PKG_CONFIG_LIBDIR}
    "${SCALED_ARM64_SYSROOT}/usr/lib/aarch64-linux-gnu/pkgconfig:${SCALED_ARM64_SYSROOT}/usr/lib/pkgconfig:${SCALED_ARM64_SYSROOT}/usr/share/pkgconfig")
  set(ENV{PKG_CONFIG_PATH} "")
  # qemu -L: the target's dynamic loader and shared libraries (OpenCV, libcamera...)
  # are the sysroot's.
  set(scaled_qemu_root "${SCALED_ARM64_SYSROOT}")
else()
  # Without a sysroot there is no arm64 OpenCV, toml++, libcamera...: say so now
  # rather than through a find_package error (try_compile projects skip this).
  get_property(scaled_in_try_compile GLOBAL PROPERTY IN_TRY_COMPILE)
  if(NOT scaled_in_try_compile AND NOT SCALED_CORE_ONLY)
    message(FATAL_ERROR "aarch64 without a sysroot builds core only: configure with "
      "-DSCALED_CORE_ONLY=ON (presets aarch64, aarch64-float), or set SCALED_ARM64_SYSROOT "
      "to a sysroot made by scripts/make-arm64-sysroot.sh (preset aarch64-sysroot)")
  endif()
  # The cross toolchain's own target tree (libc6-dev-arm64-cross and friends).
  set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu)
  # Eigen is header-only and architecture-independent: use the host's package
  # config (/usr/share/eigen3/cmake), which find_package would not look for
  # outside CMAKE_FIND_ROOT_PATH. A <Package>_DIR is used as given.
  if(NOT DEFINED Eigen3_DIR AND EXISTS /usr/share/eigen3/cmake/Eigen3Config.cmake)
    set(Eigen3_DIR /usr/share/eigen3/cmake CACHE PATH "Eigen3Config.cmake (the host's, header-only)")
  endif()
  # qemu -L: ld-linux-aarch64.so.1, libc, libstdc++ of the cross toolchain.
  set(scaled_qemu_root /usr/aarch64-linux-gnu)
endif()

if(SCALED_QEMU_AARCH64)
  set(CMAKE_CROSSCOMPILING_EMULATOR "${SCALED_QEMU_AARCH64};-L;${scaled_qemu_root}")
else()
  message(WARNING "qemu-aarch64-static not found (package qemu-user-static): "
    "the aarch64 test programs can be built but not listed or run on this host")
endif()

# Programs (pkg-config, clang-format, ...) are the host's; libraries, headers and
# package configs only the target's.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
