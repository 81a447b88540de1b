# The V4L2 camera driver (drivers/camera).
#
# camera_tests: what runs on any host, camera or not: pixel conversions
# (strides, MJPEG), pixel format names, open errors (missing node, /dev/null,
# a regular file, an unknown card name) and listV4l2Cameras().
scaled_unit_test(camera_tests
  SOURCES
    unit/drivers/camera/pixel_convert_test.cpp
    unit/drivers/camera/v4l2_camera_test.cpp
    support/allocation_counter.cpp
  LIBS scaled::camera opencv_imgcodecs opencv_imgproc
  LABELS unit drivers)

# camera_vm_tests: capture from vivid inside the QEMU VM (tests/vm/run-vm.sh
# runs it with SCALED_VM=1; vivid loaded). Not registered with ctest here:
# on the host every test skips, and the VM harness runs the binary itself.
add_executable(camera_vm_tests vm/v4l2_vm_test.cpp support/allocation_counter.cpp)
target_link_libraries(camera_vm_tests PRIVATE scaled_camera scaled_test_support scaled_warnings
  GTest::gtest GTest::gtest_main)

# vivid_feed: plays a recorded sequence into vivid's video output, looped to
# its capture, for the VM test vm.daemon_loop (tests/vm/daemon_loop_vm_test.sh).
add_executable(vivid_feed vm/vivid_feed.cpp)
target_link_libraries(vivid_feed PRIVATE scaled::dataset opencv_imgproc scaled_warnings)
