# The IMU driver (drivers/imu) and its dataset logs.
#   imu_tests     host unit tests: TUM and EuRoC logs (good and malformed),
#                 the IIO driver against a directory tree laid out like
#                 /sys/bus/iio/devices/iio:deviceN with a regular file as the
#                 character device; the vertical of a replayed sequence's maps
#                 (map_gravity.h); what feeds the gyro prior on a replay
#                 (gyro_feed.h, simulated_gyro.h). Gravity itself is core's
#                 (core_tests).
#   imu_vm_tests  the IIO driver on the kernel's iio_dummy device, sysfs and
#                 buffer (sysfs and hrtimer triggers); run inside the VM
#                 (tests/vm, vm.imu_iio), not registered with ctest here.
scaled_unit_test(imu_tests
  SOURCES
    unit/drivers/imu/imu_log_test.cpp
    unit/drivers/imu/iio_device_test.cpp
    unit/drivers/imu/map_gravity_test.cpp
    unit/drivers/imu/gyro_feed_test.cpp
  LIBS scaled::imu
  LABELS unit drivers)

add_executable(imu_vm_tests vm/imu_vm_test.cpp)
target_link_libraries(imu_vm_tests PRIVATE scaled::imu scaled_test_support scaled_warnings
  GTest::gtest GTest::gtest_main)
