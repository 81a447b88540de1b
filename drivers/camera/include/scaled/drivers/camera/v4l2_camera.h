#pragma once

// V4L2 capture: mmap streaming, poll() with a timeout, monotonic buffer
// timestamps. See camera.h for the LiveCamera contract.
//
// CameraOptions::device is a path when it contains a '/' (/dev/video0,
// /dev/v4l/by-id/...), else a card name (VIDIOC_QUERYCAP card: exact match
// first, then a unique case-insensitive substring) searched among the
// /dev/video* nodes that are single-planar video capture devices (device_caps
// when the driver reports them). Multi-planar-only nodes are not supported.
//
// Negotiation: the pixel format (kAuto: see camera.h) must be listed by
// VIDIOC_ENUM_FMT and the size by VIDIOC_ENUM_FRAMESIZES; VIDIOC_S_FMT must
// give exactly the requested format and size (strict: a calibration is for
// one size). The frame rate is the closest the device lists; when it is not
// the requested one, SequenceInfo::notes says so (as for a driver that gives
// another number of buffers, or timestamps that are not CLOCK_MONOTONIC: then
// frames are stamped at dequeue). Frame::t_ns is strictly increasing: a
// driver timestamp at or before the previous frame's becomes previous + 1 ns.
//
// Open errors name the device and the cause:
//   kNotFound         no such path; no capture device with that card name
//                     (listing those that exist, or saying there is no
//                     /dev/video* node at all)
//   kInvalidArgument  not a V4L2 device (e.g. /dev/null, a regular file), not
//                     a video capture device, format or size not offered
//                     (listing what the device offers), an ambiguous card
//                     name (listing the candidates), intrinsics of another
//                     size, a frame timeout not longer than a frame period,
//                     bad options
//   kUnavailable      busy ("busy: another program is using it", EBUSY), the
//                     device gone (ENODEV), and at reopen() a missing node or
//                     card
//   kIo               permission denied (EACCES: mentions the `video` group),
//                     other system errors
// next(): kUnavailable on device loss (ENODEV/EIO from VIDIOC_DQBUF, POLLERR,
// the node gone) or no frame within frame_timeout_s, the device then closed;
// kIo for one bad buffer (undecodable MJPEG, short buffer), naming the device
// and buffer index, the camera still streaming. Buffers the driver flags
// V4L2_BUF_FLAG_ERROR are skipped. Every ioctl and poll is retried on EINTR.
// next() converts into the Mats of the Frame it is given, in place
// (pixel_convert.h): hand it back the same Frame (or swapped Mats) and YUYV,
// NV12 and GREY capture allocates nothing per frame. reopen() after stop():
// kUnavailable.

#include <memory>
#include <vector>

#include <scaled/drivers/camera/camera.h>

namespace scaled::drivers::camera {

core::Result<std::unique_ptr<LiveCamera>> openV4l2Camera(const CameraOptions& options);

// Every /dev/video* node (natural order) that is a capture device, with one
// line per convertible format and size ("YUYV 640x480 @ 25 15 10"; ranges as
// "YUYV 16x16 to 1920x1080 step 2x2"); the formats scaled does not convert are
// named in the note. Nodes that cannot be opened are listed with a note
// ("permission denied: ...", "busy"), multi-planar ones with a note;
// metadata, output, codec and touch nodes are left out. Never fails.
std::vector<CameraDescription> listV4l2Cameras();

}  // namespace scaled::drivers::camera
