# The GPIO driver (drivers/gpio) and the status LEDs (daemon status_lights.h).
#   gpio_tests     host unit tests: patterns, StatusLights on a fake GpioOutputs,
#                  the driver's errors without a chip (this host has none).
#   gpio_vm_tests  the driver and StatusLights on a gpio-sim chip; run inside
#                  the VM (tests/vm/run-vm.sh), not registered with ctest here.

# StatusLights (daemon/src/status_lights.cpp, also part of scaled_daemon)
# compiled on its own: the tests need neither the rest of the daemon nor the
# libraries it links. Its header includes daemon_config.h, so it takes the
# daemon's usage requirements, evaluated transitively over what the daemon
# links, without building those libraries.
find_package(Threads REQUIRED)
add_library(scaled_status_lights_for_tests STATIC
  ${PROJECT_SOURCE_DIR}/daemon/src/status_lights.cpp)
target_include_directories(scaled_status_lights_for_tests PUBLIC
  ${PROJECT_SOURCE_DIR}/daemon/include
  $<TARGET_PROPERTY:scaled_daemon,INTERFACE_INCLUDE_DIRECTORIES>)
target_compile_definitions(scaled_status_lights_for_tests PUBLIC
  $<TARGET_PROPERTY:scaled_daemon,INTERFACE_COMPILE_DEFINITIONS>)
target_link_libraries(scaled_status_lights_for_tests
  PUBLIC scaled::gpio scaled::core opencv_core Threads::Threads
  PRIVATE scaled_warnings)

scaled_unit_test(gpio_tests
  SOURCES
    unit/drivers/gpio/gpio_lines_test.cpp
    unit/daemon/status_lights_test.cpp
    support/allocation_counter.cpp
  LIBS scaled_status_lights_for_tests
  LABELS unit)
target_compile_definitions(gpio_tests PRIVATE
  SCALED_GPIOD_VERSION_STRING="${SCALED_GPIOD_VERSION}")
# One binary, two areas: the pattern and StatusLights tests are the daemon's,
# the rest the driver's. ctest adds these to the label `unit` given above.
file(WRITE ${CMAKE_CURRENT_BINARY_DIR}/gpio_tests_area_labels.cmake [=[
foreach(_test IN LISTS gpio_tests_TESTS)
  if(_test MATCHES "(^|/)(LightPatternTest|StatusLightsTest)\\.")
    set_tests_properties(${_test} PROPERTIES LABELS "unit;daemon")
  else()
    set_tests_properties(${_test} PROPERTIES LABELS "unit;drivers")
  endif()
endforeach()
]=])
set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES
  ${CMAKE_CURRENT_BINARY_DIR}/gpio_tests_area_labels.cmake)

add_executable(gpio_vm_tests vm/gpio_vm_test.cpp)
target_link_libraries(gpio_vm_tests PRIVATE scaled_status_lights_for_tests scaled_test_support
  scaled_warnings GTest::gtest GTest::gtest_main)
