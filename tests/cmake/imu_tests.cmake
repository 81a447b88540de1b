# The IMU driver (drivers/imu) and its dataset logs.
#   imu_tests     host unit tests: TUM and EuRoC logs (good and malformed),
#                 the IIO driver against a directory tree laid out like
#                 /sys/bus/iio/devices/iio:deviceN with a regular file as the
#                 character device. Gravity itself is core's (core_tests).
scaled_unit_test(imu_tests
  SOURCES
    unit/drivers/imu/imu_log_test.cpp
    unit/drivers/imu/iio_device_test.cpp
  LIBS scaled::imu
  LABELS unit drivers)
