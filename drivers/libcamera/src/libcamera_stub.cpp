// libcamera_camera.h in a build without libcamera (SCALED_WITH_LIBCAMERA=OFF,
// or AUTO when pkg-config found no libcamera): the same functions, so the
// daemon links one target either way and reports the missing support at run
// time, when a configuration asks for a libcamera source.

#include <scaled/drivers/libcamera/libcamera_camera.h>

namespace scaled::drivers::libcam {

bool libcameraAvailable() {
    return false;
}

core::Result<std::unique_ptr<camera::LiveCamera>> openLibcameraCamera(
    const camera::CameraOptions& options) {
    return core::makeError(core::ErrorCode::kUnavailable,
                           "libcamera camera \"" + options.device +
                               "\": this build of scaled has no libcamera support "
                               "(rebuild with libcamera-dev)");
}

std::vector<camera::CameraDescription> listLibcameraCameras() {
    return {};
}

}  // namespace scaled::drivers::libcam
