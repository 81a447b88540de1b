#pragma once

// Depth maps of RGB-D datasets (TUM depth.txt, the 7-Scenes conversions) in
// metres.

#include <opencv2/core.hpp>

#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

// The depth image associated with `frame` (Frame::depth_path) as CV_32FC1 in
// metres: raw 16-bit value * info.depth_scale_m; 0 means no reading. Errors
// name the frame or the file: the frame has no depth image or the sequence no
// depth scale (kNotFound), the file is missing (kNotFound) or unreadable (kIo),
// or it is not a single-channel 16-bit image (kParse). Never throws.
core::Result<cv::Mat> loadDepthMetres(const source::Frame& frame, const source::SequenceInfo& info);

}  // namespace scaled::drivers::dataset
