# scalectl: reply parsing, formatting, exit codes, and the client against a
# UNIX socket served by a thread of the test (tools/scalectl).
scaled_unit_test(scalectl_tests
  SOURCES unit/tools/scalectl_test.cpp
  LIBS scaled_scalectl
  LABELS unit tools)

# The systemd units (systemd/*.in, configured by cmake/Install.cmake) pass
# `systemd-analyze verify` without a warning and keep their security exposure
# score; skipped without systemd-analyze.
add_test(NAME cli.systemd_units
  COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/cli/systemd_units_cli.sh
    ${PROJECT_SOURCE_DIR}/systemd $<TARGET_FILE:scaled>)
set_tests_properties(cli.systemd_units PROPERTIES
  LABELS "integration;systemd" SKIP_RETURN_CODE 77 TIMEOUT 120)

# `cmake --install` into a DESTDIR and `cpack -G DEB`: the expected files,
# conffiles and dependencies; skipped without dpkg-deb or cpack.
add_test(NAME cli.package
  COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/cli/package_cli.sh ${PROJECT_BINARY_DIR}
    ${CMAKE_COMMAND} ${CMAKE_CPACK_COMMAND})
set_tests_properties(cli.package PROPERTIES
  LABELS "integration;package" SKIP_RETURN_CODE 77 TIMEOUT 600)
