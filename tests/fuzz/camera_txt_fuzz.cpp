// camera.txt (`width height fx fy cx cy [k1 k2]`, TUM datasets and image
// folders; parseTumCameraFile, drivers/src/dataset_tum.cpp): what it accepts
// is a camera core accepts, with an integer image size in [1, 100000].

#include <cstddef>
#include <cstdint>
#include <string_view>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/drivers/dataset/dataset_tum.h>

#include "fuzz_support.h"

using scaled::fuzz::check;
using scaled::fuzz::isFinite;

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto k = scaled::drivers::dataset::parseTumCameraFile(scaled::fuzz::asText(data, size),
                                                                "d/camera.txt");
    if (!k) {
        check(scaled::fuzz::startsWith(k.error().message, "d/camera.txt"),
              "an error names the file");
        return 0;
    }
    check(k->width_px >= 1 && k->width_px <= 100000 && k->height_px >= 1 && k->height_px <= 100000,
          "the image size is in [1, 100000]");
    check(isFinite(k->fx) && isFinite(k->fy) && isFinite(k->cx) && isFinite(k->cy) &&
              isFinite(k->k1) && isFinite(k->k2),
          "the intrinsics are finite");
    check(scaled::core::PinholeRadialCamera::create(*k).ok(), "core accepts the camera");
    return 0;
}
