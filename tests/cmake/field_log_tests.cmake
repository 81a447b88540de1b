# The field log: the writer and reader are in drivers_tests
# (unit/drivers/field_log_test.cpp), the log service in daemon_tests
# (unit/daemon/log_service_test.cpp); here the field-log tool end to end.
add_test(NAME cli.field_log COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/cli/field_log_cli.sh
  $<TARGET_FILE:field-log>)
set_tests_properties(cli.field_log PROPERTIES LABELS "integration;tools" TIMEOUT 300)
