# The daemon's configuration: `scaled --check-config` on config/scaled.toml
# and on broken files (exit 78, errors naming file, line and key). The unit
# tests are in daemon_tests (unit/daemon/daemon_config_test.cpp).
add_test(NAME cli.scaled_check_config
  COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/cli/scaled_check_config_cli.sh
    $<TARGET_FILE:scaled> ${PROJECT_SOURCE_DIR})
set_tests_properties(cli.scaled_check_config PROPERTIES LABELS "integration;daemon")
