# The libcamera driver (drivers/libcamera). The host has no cameras: the host
# tests check the errors, the listing, the CameraManager sharing and the frame
# conversion, or, in a build without libcamera (-DSCALED_WITH_LIBCAMERA=OFF),
# the stub. frame_convert.h is the driver's internal header, hence its source
# directory.
get_property(scaled_have_libcamera GLOBAL PROPERTY SCALED_HAVE_LIBCAMERA)

scaled_unit_test(libcamera_tests
  SOURCES
    unit/drivers/libcamera/libcamera_camera_test.cpp
    unit/drivers/libcamera/frame_convert_test.cpp
    support/allocation_counter.cpp
  LIBS scaled::libcamera opencv_core opencv_imgproc
  LABELS unit drivers)
target_include_directories(libcamera_tests PRIVATE ${PROJECT_SOURCE_DIR}/drivers/libcamera/src)

# The guest side: run inside the VM (tests/vm/run-vm.sh) where vimc provides a
# camera, with SCALED_VM=1; not registered with ctest (it skips outside the
# VM and would only say so).
if(scaled_have_libcamera)
  add_executable(libcamera_vm_tests vm/libcamera_vm_test.cpp)
  target_link_libraries(libcamera_vm_tests PRIVATE scaled_libcamera scaled_test_support
                        scaled_warnings GTest::gtest GTest::gtest_main)
endif()
