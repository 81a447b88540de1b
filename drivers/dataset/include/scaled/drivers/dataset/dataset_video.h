#pragma once

// A video file, decoded with cv::VideoCapture (whichever backend the OpenCV
// build has for it: FFmpeg, GStreamer, OpenCV's own MJPEG reader):
//
//   Frames       gray (CV_8UC1) and color (CV_8UC3 BGR) views of each decoded
//                frame; Frame::id is the 0-based frame index in the file.
//   Timestamps   t_ns of a frame is the container's time of that frame
//                (CAP_PROP_POS_MSEC after grabbing it) when it is finite, >= 0
//                and later than the previous frame's; otherwise the previous
//                frame's time plus one frame period per frame since (frame 0:
//                0). The period is 1 / CAP_PROP_FPS, or 1 /
//                DatasetOptions::folder_fps when the container gives no frame
//                rate. So a file with usable container times keeps them, one
//                without gets index / fps, and t_ns always strictly increases.
//   frame_count  CAP_PROP_FRAME_COUNT, which containers may only estimate
//                (from duration x frame rate): next() returns at most that
//                many frames and returns false cleanly where the stream really
//                ends, even if earlier (a note then says so). When the
//                container gives no count, the frames are counted at open by
//                grabbing them all (slow for long videos; a note says so).
//   seek(i)      exact: reopens the file when going back and grabs (without
//                converting) forward to frame i. CAP_PROP_POS_FRAMES is not
//                used: FFmpeg seeks to key frames and lands near, not on, the
//                frame for many codecs.
//   Intrinsics   DatasetOptions::intrinsics, else camera.txt in the video's
//                directory (`width height fx fy cx cy [k1 k2]`, as TUM's), else
//                has_intrinsics is false. A zero size is taken from frame 0.
//
// Errors never throw (every cv::Exception is caught): a file that cannot be
// opened is kIo naming it; one whose frame 0 cannot be decoded is kParse
// naming it; a frame that fails to decode mid-stream is an error of next()
// naming the file and the frame index, and the cursor moves past it (up to 32
// consecutive undecodable frames; more are taken as the end).

#include <filesystem>
#include <memory>

#include <scaled/core/result.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

core::Result<std::unique_ptr<source::FrameSource>> openVideo(const std::filesystem::path& file,
                                                             const DatasetOptions& opt = {});

}  // namespace scaled::drivers::dataset
