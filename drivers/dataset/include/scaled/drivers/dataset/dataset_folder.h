#pragma once

// A plain directory of images (a phone's burst, frames exported from a video):
//
//   *.png *.jpg *.jpeg *.pgm *.ppm *.bmp *.tif *.tiff   the frames (any case of the
//                    extension), in natural order ("img2" before "img10"); other
//                    files, subdirectories and hidden files (".name") are ignored
//   times.txt        optional, one time in seconds per line, strictly increasing
//                    (same rules as KITTI's): line N times the N-th image. Without
//                    it frame i is at i / DatasetOptions::folder_fps seconds.
//   camera.txt       optional, `width height fx fy cx cy [k1 k2]` (as TUM's);
//                    DatasetOptions::intrinsics overrides it; with neither,
//                    SequenceInfo::has_intrinsics is false.
//
// The listing is taken once, in openImageFolder(). A folder without images is
// an error naming it; an image that cannot be decoded is an error of next()
// naming the file. See frame_source.h for the error format.

#include <filesystem>
#include <memory>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

core::Result<std::unique_ptr<source::FrameSource>> openImageFolder(const std::filesystem::path& dir,
                                                                   const DatasetOptions& opt = {});

// True when the file name ends in one of the image extensions above (any case).
bool isImageFileName(const std::filesystem::path& name);

// Natural order: runs of digits compare as numbers ("img2" < "img10", "a01" and
// "a1" equal), everything else character by character ignoring ASCII case;
// names that compare equal that way are ordered by plain byte comparison.
bool naturalLess(std::string_view a, std::string_view b);

// The image files directly in `dir` (see above for which), in natural order of
// their names. Errors name the directory.
core::Result<std::vector<std::filesystem::path>> listImageFiles(const std::filesystem::path& dir);

}  // namespace scaled::drivers::dataset
