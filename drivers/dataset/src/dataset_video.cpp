#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <opencv2/videoio.hpp>
#include <opencv2/videoio/registry.hpp>
#include <optional>
#include <string>
#include <system_error>
#include <utility>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/dataset_video.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

// The OpenCV backends that read video files, in order of preference. CAP_ANY
// would also try camera backends on a file name (V4L2, and GPHOTO2, which
// enumerates USB devices through libusb and leaks doing so) and CV_IMAGES
// (which takes a printf pattern in the name for an image sequence).
constexpr std::array<cv::VideoCaptureAPIs, 3> kFileBackends = {cv::CAP_FFMPEG, cv::CAP_GSTREAMER,
                                                               cv::CAP_OPENCV_MJPEG};

// Opens `file` with the first file backend that reads it. Never throws.
bool openVideoFile(cv::VideoCapture& cap, const std::string& file) {
    for (const cv::VideoCaptureAPIs api : kFileBackends) {
        if (!cv::videoio_registry::hasBackend(api)) {
            continue;
        }
        try {
            if (cap.open(file, api) && cap.isOpened()) {
                return true;
            }
        } catch (const cv::Exception&) {
            // this backend cannot read it: try the next one
        }
        cap.release();
    }
    return false;
}

// Consecutive frames that fail to decode before the stream is taken as ended.
constexpr std::size_t kMaxBadRun = 32;
// Container values beyond these are taken as "unknown".
constexpr double kMaxFrameCount = 1e9;
constexpr double kMaxFps = 1e9;
constexpr double kMaxMs = 9.0e12;  // 9e18 ns, below INT64_MAX

std::string what(const std::exception& e) {
    return std::string(e.what());
}

struct Decoded {
    std::size_t index = 0;
    int64_t t_ns = 0;
    cv::Mat image;
};

class VideoSource final : public source::FrameSource {
public:
    explicit VideoSource(std::filesystem::path file)
        : file_(std::move(file)), name_(file_.string()) {
        info_.name = file_.filename().string();
        info_.dir = file_.parent_path();
    }

    [[nodiscard]] const source::SequenceInfo& info() const override { return info_; }
    source::SequenceInfo& mutableInfo() { return info_; }

    // Opens the file, reads the frame rate and count from the container and
    // decodes frame 0 (kept for the first next()).
    Result<cv::Mat> start(double default_fps) {
        if (auto opened = reopen(); !opened) {
            return opened.error();
        }
        double container_fps = 0;
        double container_count = 0;
        try {
            container_fps = cap_.get(cv::CAP_PROP_FPS);
            container_count = cap_.get(cv::CAP_PROP_FRAME_COUNT);
        } catch (const std::exception& e) {
            return makeError(ErrorCode::kIo,
                             name_ + ": cannot read the video's properties: " + what(e));
        }
        double fps = default_fps;
        if (std::isfinite(container_fps) && container_fps > 0 && container_fps <= kMaxFps) {
            fps = container_fps;
            info_.notes.push_back(name_ + ": timestamps from the container, else frame index / " +
                                  detail::shortNumber(fps) + " Hz (the container's frame rate)");
        } else {
            info_.notes.push_back(name_ +
                                  ": the container gives no frame rate: timestamps from the "
                                  "container, else frame index / " +
                                  detail::shortNumber(fps) + " Hz (DatasetOptions.folder_fps)");
        }
        period_ns_ = 1e9 / fps;
        if (std::isfinite(container_count) && container_count >= 1 &&
            container_count <= kMaxFrameCount) {
            frame_count_ = static_cast<std::size_t>(std::llround(container_count));
        } else {
            auto counted = countFrames();
            if (!counted) {
                return counted.error();
            }
            frame_count_ = *counted;
            info_.notes.push_back(name_ + ": the container gives no frame count: counted " +
                                  std::to_string(frame_count_) + " frames by decoding them");
        }
        if (frame_count_ == 0) {
            return makeError(ErrorCode::kParse, name_ + ": the video has no frames");
        }
        info_.frame_count = frame_count_;
        info_.listed_count = frame_count_;
        auto got = grab();
        if (!got) {
            return got.error();
        }
        if (!*got) {
            return makeError(ErrorCode::kParse, name_ + ": cannot decode the first frame");
        }
        auto img = retrieve(0);
        if (!img) {
            return img.error();
        }
        pending_ = Decoded{0, grabbed_t_ns_, *img};
        return *img;
    }

    Result<bool> next(source::Frame& frame) override {
        if (ended_ || cursor_ >= frame_count_) {
            return false;
        }
        if (pending_ && pending_->index == cursor_) {
            Decoded d = std::move(*pending_);
            pending_.reset();
            ++cursor_;
            return emit(d, frame);
        }
        const std::size_t i = cursor_;
        auto got = grab();
        if (!got) {
            ++cursor_;
            return got.error();
        }
        if (*got) {
            const int64_t t_ns = grabbed_t_ns_;
            ++cursor_;
            auto img = retrieve(i);
            if (!img) {
                return img.error();
            }
            return emit(Decoded{i, t_ns, *img}, frame);
        }
        // No frame: the end of the stream, or (FFmpeg decodes in grab()) a
        // frame that cannot be decoded. Look ahead for a decodable one.
        for (std::size_t k = 1; k <= kMaxBadRun && i + k < frame_count_; ++k) {
            auto ahead = grab();
            if (!ahead) {
                cursor_ = i + k + 1;
                return ahead.error();
            }
            if (!*ahead) {
                continue;
            }
            const int64_t t_ns = grabbed_t_ns_;
            auto img = retrieve(i + k);
            if (!img) {
                continue;  // undecodable too
            }
            pending_ = Decoded{i + k, t_ns, *img};
            cursor_ = i + k;
            const std::string which =
                k == 1 ? "frame " + std::to_string(i)
                       : "frames " + std::to_string(i) + " to " + std::to_string(i + k - 1);
            return makeError(ErrorCode::kParse, name_ + ": " + which + ": cannot decode");
        }
        ended_ = true;
        if (!end_noted_) {
            end_noted_ = true;
            info_.notes.push_back(name_ + ": the video ends after " + std::to_string(i) +
                                  " frames (the container announced " +
                                  std::to_string(frame_count_) + ")");
        }
        return false;
    }

    Result<bool> seek(std::size_t index) override {
        if (index > frame_count_) {
            return makeError(ErrorCode::kInvalidArgument,
                             info_.name + ": cannot seek to frame " + std::to_string(index) +
                                 ": the video has " + std::to_string(frame_count_) + " frames");
        }
        if (index == frame_count_) {
            cursor_ = index;
            ended_ = true;
            pending_.reset();
            return false;
        }
        if (!ended_ && index == cursor_) {
            return true;
        }
        if (ended_ || pending_ || index < cursor_) {
            if (auto opened = reopen(); !opened) {
                return opened.error();
            }
        }
        // Grab (no colour conversion) up to the frame; a frame that fails to
        // decode counts as a frame, as in next().
        while (cursor_ < index) {
            auto got = grab();
            if (!got) {
                return got.error();
            }
            ++cursor_;
        }
        return true;
    }

private:
    Status reopen() {
        try {
            cap_.release();
            if (!openVideoFile(cap_, file_.string())) {
                return makeError(ErrorCode::kIo,
                                 name_ + ": cannot open as a video (no OpenCV backend reads it)");
            }
        } catch (const std::exception& e) {
            return makeError(ErrorCode::kIo, name_ + ": cannot open as a video: " + what(e));
        }
        cursor_ = 0;
        pos_ = 0;
        last_t_ns_.reset();
        last_index_ = 0;
        ended_ = false;
        pending_.reset();
        return {};
    }

    // Grabs the frame at pos_; true: grabbed, its time in grabbed_t_ns_.
    Result<bool> grab() {
        const std::size_t index = pos_++;
        bool ok = false;
        double ms = std::nan("");
        try {
            ok = cap_.grab();
            if (ok) {
                ms = cap_.get(cv::CAP_PROP_POS_MSEC);
            }
        } catch (const std::exception& e) {
            return makeError(ErrorCode::kIo,
                             name_ + ": frame " + std::to_string(index) + ": " + what(e));
        }
        if (!ok) {
            return false;
        }
        // Container time when it is usable and increases; else advance by the
        // frame period.
        const int64_t fallback =
            last_t_ns_
                ? *last_t_ns_ + static_cast<int64_t>(std::llround(
                                    static_cast<double>(index - last_index_) * period_ns_))
                : static_cast<int64_t>(std::llround(static_cast<double>(index) * period_ns_));
        int64_t t_ns = fallback;
        if (std::isfinite(ms) && ms >= 0 && ms <= kMaxMs) {
            const auto container = static_cast<int64_t>(std::llround(ms * 1e6));
            if (!last_t_ns_ || container > *last_t_ns_) {
                t_ns = container;
            }
        }
        if (last_t_ns_ && t_ns <= *last_t_ns_) {
            t_ns = *last_t_ns_ + 1;
        }
        last_t_ns_ = t_ns;
        last_index_ = index;
        grabbed_t_ns_ = t_ns;
        return true;
    }

    Result<cv::Mat> retrieve(std::size_t index) {
        cv::Mat img;
        try {
            if (!cap_.retrieve(img) || img.empty()) {
                return makeError(ErrorCode::kParse,
                                 name_ + ": frame " + std::to_string(index) + ": cannot decode");
            }
        } catch (const std::exception& e) {
            return makeError(ErrorCode::kParse, name_ + ": frame " + std::to_string(index) +
                                                    ": cannot decode: " + what(e));
        }
        return img;
    }

    Result<bool> emit(const Decoded& d, source::Frame& frame) {
        const std::string source = name_ + ": frame " + std::to_string(d.index);
        if (info_.has_intrinsics && (d.image.cols != info_.intrinsics.width_px ||
                                     d.image.rows != info_.intrinsics.height_px)) {
            return makeError(
                ErrorCode::kInvalidArgument,
                source + ": image is " + detail::sizeText(d.image.cols, d.image.rows) +
                    " but the intrinsics are for " +
                    detail::sizeText(info_.intrinsics.width_px, info_.intrinsics.height_px));
        }
        source::Frame out;
        if (auto split = detail::toGrayAndColor(d.image, source, out); !split) {
            return split.error();
        }
        out.id = static_cast<int64_t>(d.index);
        out.t_ns = d.t_ns;
        out.image_path = file_;
        frame = std::move(out);
        return true;
    }

    // Frames counted by grabbing them all, for containers that give no count.
    Result<std::size_t> countFrames() const {
        try {
            cv::VideoCapture cap;
            if (!openVideoFile(cap, file_.string())) {
                return makeError(ErrorCode::kIo, name_ + ": cannot open the video");
            }
            std::size_t n = 0;
            std::size_t bad_run = 0;
            for (std::size_t i = 0; bad_run <= kMaxBadRun; ++i) {
                if (cap.grab()) {
                    n = i + 1;
                    bad_run = 0;
                } else {
                    ++bad_run;
                }
            }
            return n;
        } catch (const std::exception& e) {
            return makeError(ErrorCode::kIo, name_ + ": cannot count the frames: " + what(e));
        }
    }

    std::filesystem::path file_;
    std::string name_;  // the file, for messages
    source::SequenceInfo info_;
    double period_ns_ = 0;
    std::size_t frame_count_ = 0;
    cv::VideoCapture cap_;
    std::size_t cursor_ = 0;  // frame next() returns
    std::size_t pos_ = 0;     // frame the capture's next grab() yields
    std::optional<int64_t> last_t_ns_;
    std::size_t last_index_ = 0;
    int64_t grabbed_t_ns_ = 0;
    bool ended_ = false;
    bool end_noted_ = false;
    std::optional<Decoded> pending_;
};

}  // namespace

Result<std::unique_ptr<source::FrameSource>> openVideo(const std::filesystem::path& file,
                                                       const DatasetOptions& opt) {
    if (auto fps = detail::validateFps(opt.folder_fps); !fps) {
        return fps.error();
    }
    std::error_code ec;
    const auto status = std::filesystem::status(file, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kNotFound, file.string() + ": video file not found");
    }
    if (!std::filesystem::is_regular_file(status)) {
        return makeError(ErrorCode::kIo, file.string() + ": not a regular file");
    }

    auto source = std::make_unique<VideoSource>(file);
    auto first = source->start(opt.folder_fps);
    if (!first) {
        return first.error();
    }

    const std::filesystem::path camera_file = file.parent_path() / "camera.txt";
    auto from_dataset = readOptionalCameraFile(camera_file);
    if (!from_dataset) {
        return from_dataset.error();
    }
    if (auto resolved =
            detail::chooseIntrinsics(source->mutableInfo(), *from_dataset, camera_file.string(),
                                     opt, [&]() -> Result<cv::Size> { return first->size(); });
        !resolved) {
        return resolved.error();
    }
    return std::unique_ptr<source::FrameSource>(std::move(source));
}

}  // namespace scaled::drivers::dataset
