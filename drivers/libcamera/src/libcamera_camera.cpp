// The libcamera driver. Threads: next(), reopen() and the destructor run on
// the caller's capture thread; libcamera calls onRequestCompleted() and
// onDisconnected() on its own thread (the CameraManager's); stop(), describe()
// and mode() may come from any thread. The completion handler only queues
// the request; conversion and requeueing happen in next().
//
// libcamera reports errors as negative errno values and null pointers (it
// does not throw); every one is checked here and turned into a message that
// names the camera.
//
// API kept to what libcamera 0.0.3 (Debian bookworm) and the later releases
// (0.1 .. 0.5, the Raspberry Pi fork) all have: generateConfiguration() gets a
// std::vector<StreamRole> (a StreamRoles in 0.0.x, converted to the Span of
// later releases), FrameDurationLimits is a Span<const int64_t, 2>, requests
// are recycled with Request::ReuseBuffers, and the transform/orientation
// field (renamed in 0.2) is left at its default.

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <libcamera/camera.h>
#include <libcamera/camera_manager.h>
#include <libcamera/control_ids.h>
#include <libcamera/controls.h>
#include <libcamera/formats.h>
#include <libcamera/framebuffer.h>
#include <libcamera/framebuffer_allocator.h>
#include <libcamera/property_ids.h>
#include <libcamera/request.h>
#include <libcamera/stream.h>
#include <map>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <sys/mman.h>
#include <system_error>
#include <utility>
#include <vector>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/libcamera/libcamera_camera.h>

#include "frame_convert.h"

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;
using core::makeError;

using base::errnoText;

std::string quoted(const std::string& text) {
    return "\"" + text + "\"";
}

std::string sizeText(const libcamera::Size& size) {
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// "30", "7.5": frame rates in messages and mode().
std::string fpsText(double fps) {
    std::array<char, 32> text{};
    std::snprintf(text.data(), text.size(), "%.4g", fps);
    return text.data();
}

std::string secondsText(double seconds) {
    std::array<char, 32> text{};
    std::snprintf(text.data(), text.size(), "%.1f", seconds);
    return text.data();
}

int64_t monotonicNowNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// scaled's formats and libcamera's constants for them (an invalid
// libcamera::PixelFormat for those the driver does not convert).
libcamera::PixelFormat libcameraFormat(camera::PixelFormat format) {
    switch (format) {
        case camera::PixelFormat::kYuyv:
            return libcamera::formats::YUYV;
        case camera::PixelFormat::kNv12:
            return libcamera::formats::NV12;
        case camera::PixelFormat::kYuv420:
            return libcamera::formats::YUV420;
        case camera::PixelFormat::kRgb888:
            return libcamera::formats::RGB888;
        case camera::PixelFormat::kBgr888:
            return libcamera::formats::BGR888;
        case camera::PixelFormat::kXrgb8888:
            return libcamera::formats::XRGB8888;
        case camera::PixelFormat::kXbgr8888:
            return libcamera::formats::XBGR8888;
        case camera::PixelFormat::kAuto:
        case camera::PixelFormat::kMjpeg:
        case camera::PixelFormat::kGrey:
            break;
    }
    return {};
}

std::optional<camera::PixelFormat> scaledFormat(const libcamera::PixelFormat& format) {
    for (const camera::PixelFormat f : libcam::preferredFormats()) {
        if (libcameraFormat(f) == format) {
            return f;
        }
    }
    return std::nullopt;
}

// ---------------------------------------------------------------------------
// The process's CameraManager. libcamera allows one at a time (a second one
// is a fatal error that aborts), and both listLibcameraCameras() and every
// open camera need it: they share this one, which is started on first use
// and stopped when the last user lets go. A new one is only created after
// the previous one has been destroyed (`exists`).

struct ManagerHolder {
    std::mutex mutex;
    std::condition_variable gone;
    std::weak_ptr<libcamera::CameraManager> manager;
    bool exists = false;
};

ManagerHolder& managerHolder() {
    // Never destroyed: a camera may let go of the manager while the process
    // exits, after function-local statics have been destroyed.
    static auto* holder = new ManagerHolder();
    return *holder;
}

// libcamera logs INFO and WARN lines to stderr from the moment it starts,
// which buries the daemon's own messages. Quiet it to errors, unless the user
// chose levels: LIBCAMERA_LOG_LEVELS from the environment (e.g. "*:DEBUG" to
// debug a camera) wins, as setenv() with overwrite 0 keeps it. libcamera reads
// the variable once, when its logger is first used, which is the
// CameraManager created below. (setenv() is not safe against concurrent
// getenv() in other threads; it runs at most once per manager, under the
// holder's mutex, normally while the daemon starts.)
void quietLibcameraLogs() {
    ::setenv("LIBCAMERA_LOG_LEVELS", "*:ERROR", 0);
}

core::Result<std::shared_ptr<libcamera::CameraManager>> sharedManager() {
    ManagerHolder& holder = managerHolder();
    std::unique_lock lock(holder.mutex);
    for (;;) {
        if (auto manager = holder.manager.lock()) {
            return manager;
        }
        if (!holder.exists) {
            break;
        }
        holder.gone.wait(lock);  // the last user is stopping the previous one
    }
    quietLibcameraLogs();
    auto manager = std::make_unique<libcamera::CameraManager>();
    const int rc = manager->start();
    if (rc < 0) {
        return makeError(ErrorCode::kUnavailable,
                         "libcamera: cannot start the camera manager: " + errnoText(-rc));
    }
    std::shared_ptr<libcamera::CameraManager> shared(
        manager.release(), [](libcamera::CameraManager* done) {
            done->stop();
            delete done;
            ManagerHolder& h = managerHolder();
            {
                const std::lock_guard done_lock(h.mutex);
                h.exists = false;
            }
            h.gone.notify_all();
        });
    holder.manager = shared;
    holder.exists = true;
    return shared;
}

// Keeps what libcamera may still use after a camera vanished mid-stream
// (requests, buffers) alive until the process ends: a bounded leak per
// unplugged camera instead of a use after free.
void bury(std::shared_ptr<void> remains) {
    static auto* mutex = new std::mutex();
    static auto* graveyard = new std::vector<std::shared_ptr<void>>();
    const std::lock_guard lock(*mutex);
    graveyard->push_back(std::move(remains));
}

// ---------------------------------------------------------------------------
// Cameras by index or id.

std::string modelOf(const libcamera::Camera& camera) {
    const auto model = camera.properties().get(libcamera::properties::Model);
    return model ? *model : std::string();
}

std::string locationOf(const libcamera::Camera& camera) {
    const auto location = camera.properties().get(libcamera::properties::Location);
    if (!location) {
        return {};
    }
    switch (*location) {
        case libcamera::properties::CameraLocationFront:
            return "front";
        case libcamera::properties::CameraLocationBack:
            return "back";
        case libcamera::properties::CameraLocationExternal:
            return "external";
        default:
            return "location " + std::to_string(*location);
    }
}

// `0: "platform/vimc.0 Sensor B" (Sensor B), 1: ...`
std::string cameraList(const std::vector<std::shared_ptr<libcamera::Camera>>& cameras) {
    std::string text;
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        if (i > 0) {
            text += ", ";
        }
        text += std::to_string(i) + ": " + quoted(cameras[i]->id());
        const std::string model = modelOf(*cameras[i]);
        if (!model.empty()) {
            text += " (" + model + ")";
        }
    }
    return text;
}

core::Error noCameras(const std::string& who) {
    return makeError(ErrorCode::kNotFound,
                     who +
                         ": no cameras (libcamera lists only the devices udev has seen: is the "
                         "camera connected, its driver loaded and udev running?)");
}

core::Result<std::shared_ptr<libcamera::Camera>> findCamera(libcamera::CameraManager& manager,
                                                            const std::string& device) {
    const std::string who = "libcamera camera " + quoted(device);
    const std::vector<std::shared_ptr<libcamera::Camera>> cameras = manager.cameras();
    if (cameras.empty()) {
        return noCameras(who);
    }
    if (device.empty()) {
        return makeError(
            ErrorCode::kInvalidArgument,
            "libcamera: no camera given; use an index (\"0\") or an id of: " + cameraList(cameras));
    }
    if (std::all_of(device.begin(), device.end(), [](char c) { return c >= '0' && c <= '9'; })) {
        std::size_t index = 0;
        const auto [end, ec] = std::from_chars(device.data(), device.data() + device.size(), index);
        if (ec != std::errc() || end != device.data() + device.size() || index >= cameras.size()) {
            return makeError(ErrorCode::kNotFound,
                             who + ": no camera with that index; cameras: " + cameraList(cameras));
        }
        return cameras[index];
    }
    for (const auto& camera : cameras) {
        if (camera->id() == device) {
            return camera;
        }
    }
    std::vector<std::shared_ptr<libcamera::Camera>> matches;
    for (const auto& camera : cameras) {
        if (camera->id().find(device) != std::string::npos) {
            matches.push_back(camera);
        }
    }
    if (matches.size() == 1) {
        return matches.front();
    }
    if (matches.empty()) {
        return makeError(ErrorCode::kNotFound,
                         who + ": no camera with that id; cameras: " + cameraList(cameras));
    }
    return makeError(
        ErrorCode::kInvalidArgument,
        who + ": matches several cameras, give more of the id: " + cameraList(matches));
}

// The stream configuration scaled asks for: a viewfinder, else a video stream.
std::unique_ptr<libcamera::CameraConfiguration> generateStreamConfiguration(
    libcamera::Camera& camera) {
    for (const libcamera::StreamRole role :
         {libcamera::StreamRole::Viewfinder, libcamera::StreamRole::VideoRecording}) {
        // A named vector: libcamera 0.0.x takes a StreamRoles (a vector), later
        // releases a Span<const StreamRole>, which a vector converts to.
        const std::vector<libcamera::StreamRole> roles{role};
        auto config = camera.generateConfiguration(roles);
        if (config && !config->empty()) {
            return config;
        }
    }
    return nullptr;
}

// ---------------------------------------------------------------------------

class LibcameraCamera final : public camera::LiveCamera {
public:
    LibcameraCamera(camera::CameraOptions options,
                    std::shared_ptr<libcamera::CameraManager> manager, std::string id)
        : options_(std::move(options)), manager_(std::move(manager)), id_(std::move(id)) {
        info_.name = id_;
        info_.frame_count = 0;  // live: no end
        info_.listed_count = 0;
    }

    ~LibcameraCamera() override {
        closeSession();
        // The manager goes last (closeSession() has released the camera).
        manager_.reset();
    }

    LibcameraCamera(const LibcameraCamera&) = delete;
    LibcameraCamera& operator=(const LibcameraCamera&) = delete;
    LibcameraCamera(LibcameraCamera&&) = delete;
    LibcameraCamera& operator=(LibcameraCamera&&) = delete;

    [[nodiscard]] const source::SequenceInfo& info() const override { return info_; }

    [[nodiscard]] std::string describe() const override {
        return "camera " + quoted(id_) + " (libcamera)";
    }

    [[nodiscard]] std::string mode() const override {
        const std::lock_guard lock(mutex_);
        return mode_;
    }

    // The first open: a session, then the SequenceInfo (notes, intrinsics).
    core::Status open() {
        auto started = openSession();
        if (!started) {
            return started;
        }
        if (options_.has_intrinsics && (options_.intrinsics.width_px != width_px_ ||
                                        options_.intrinsics.height_px != height_px_)) {
            const std::string calibrated = std::to_string(options_.intrinsics.width_px) + "x" +
                                           std::to_string(options_.intrinsics.height_px);
            closeSession();
            return makeError(ErrorCode::kInvalidArgument,
                             describe() + ": the intrinsics are for " + calibrated +
                                 " but the camera delivers " + std::to_string(width_px_) + "x" +
                                 std::to_string(height_px_));
        }
        info_.intrinsics = options_.intrinsics;
        info_.has_intrinsics = options_.has_intrinsics;
        info_.notes = session_notes_;
        first_width_px_ = width_px_;
        first_height_px_ = height_px_;
        return {};
    }

    core::Result<bool> next(source::Frame& frame) override {
        std::unique_lock lock(mutex_);
        if (stopped_) {
            return false;
        }
        if (!started_) {
            return makeError(ErrorCode::kUnavailable,
                             describe() + ": closed after an earlier error; call reopen()");
        }
        const auto deadline = std::chrono::steady_clock::now() +
                              std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                  std::chrono::duration<double>(options_.frame_timeout_s));
        for (;;) {
            cv_.wait_until(lock, deadline,
                           [this] { return stopped_ || disconnected_ || queued_ > 0; });
            if (stopped_) {
                return false;
            }
            if (disconnected_) {
                lock.unlock();
                closeSession();
                return makeError(ErrorCode::kUnavailable,
                                 describe() + ": device lost (disconnected)");
            }
            if (queued_ == 0) {
                lock.unlock();
                closeSession();
                return makeError(
                    ErrorCode::kUnavailable,
                    describe() + ": no frame for " + secondsText(options_.frame_timeout_s) + " s");
            }
            libcamera::Request* request = completed_[head_];
            head_ = (head_ + 1) % completed_.size();
            --queued_;
            lock.unlock();
            auto delivered = deliver(request, frame);
            if (!delivered || *delivered) {
                return delivered;
            }
            lock.lock();  // a cancelled request, requeued: wait for the next one
        }
    }

    core::Result<bool> reopen() override {
        closeSession();
        {
            const std::lock_guard lock(mutex_);
            stopped_ = false;
        }
        auto started = openSession();
        if (!started) {
            return started.error();
        }
        if (width_px_ != first_width_px_ || height_px_ != first_height_px_) {
            const std::string now = std::to_string(width_px_) + "x" + std::to_string(height_px_);
            closeSession();
            return makeError(ErrorCode::kInvalidArgument,
                             describe() + ": came back with size " + now + " instead of " +
                                 std::to_string(first_width_px_) + "x" +
                                 std::to_string(first_height_px_));
        }
        return true;
    }

    void stop() override {
        {
            const std::lock_guard lock(mutex_);
            stopped_ = true;
        }
        cv_.notify_all();
    }

private:
    // One mapping of a dmabuf.
    struct Mapping {
        void* address = nullptr;
        std::size_t length = 0;
    };

    core::Error error(ErrorCode code, const std::string& what) const {
        return makeError(code, describe() + ": " + what);
    }

    core::Error libcameraError(const std::string& what, int rc) const {
        const int err = -rc;
        const ErrorCode code = (err == ENODEV || err == EBUSY || err == EIO)
                                   ? ErrorCode::kUnavailable
                                   : ErrorCode::kIo;
        return error(code, what + ": " + errnoText(err));
    }

    core::Status openSession() {
        auto started = startSession();
        if (!started) {
            closeSession();
        }
        return started;
    }

    // acquire, configure, allocate and map buffers, create requests, start,
    // queue every request. On error the caller closes what was opened.
    core::Status startSession() {
        session_notes_.clear();
        {
            const std::lock_guard lock(mutex_);
            disconnected_ = false;
            head_ = 0;
            queued_ = 0;
        }
        camera_ = manager_->get(id_);
        if (!camera_) {
            const auto cameras = manager_->cameras();
            return error(ErrorCode::kUnavailable,
                         "not found (disconnected?); cameras now: " +
                             (cameras.empty() ? std::string("none") : cameraList(cameras)));
        }
        const int acquired = camera_->acquire();
        if (acquired == -EBUSY) {
            return error(ErrorCode::kUnavailable,
                         "camera busy (another process, or another source of this one, uses it)");
        }
        if (acquired < 0) {
            return libcameraError("cannot acquire the camera", acquired);
        }
        acquired_ = true;

        auto configured = configureStream();
        if (!configured) {
            return configured;
        }
        auto allocated = allocateBuffers();
        if (!allocated) {
            return allocated;
        }
        camera_->requestCompleted.connect(this, &LibcameraCamera::onRequestCompleted);
        camera_->disconnected.connect(this, &LibcameraCamera::onDisconnected);
        connected_ = true;

        libcamera::ControlList controls(camera_->controls());
        const double fps = frameRateControl(controls);
        const int started = camera_->start(&controls);
        if (started < 0) {
            return libcameraError("cannot start the camera", started);
        }
        started_ = true;
        for (const auto& request : requests_) {
            const int queued = camera_->queueRequest(request.get());
            if (queued < 0) {
                return libcameraError("cannot queue a request", queued);
            }
        }
        const std::lock_guard lock(mutex_);
        mode_ = std::string(toString(format_)) + " " + std::to_string(width_px_) + "x" +
                std::to_string(height_px_) + " @ " +
                (fps > 0 ? fpsText(fps) : std::string("the camera's rate"));
        return {};
    }

    // The formats to try, in order: the option's, or the preferred ones for auto.
    core::Result<std::vector<camera::PixelFormat>> wantedFormats() const {
        std::vector<camera::PixelFormat> wanted;
        switch (options_.pixel_format) {
            case camera::PixelFormat::kAuto: {
                const auto preferred = libcam::preferredFormats();
                wanted.assign(preferred.begin(), preferred.end());
                break;
            }
            case camera::PixelFormat::kYuyv:
            case camera::PixelFormat::kNv12:
            case camera::PixelFormat::kYuv420:
            case camera::PixelFormat::kRgb888:
            case camera::PixelFormat::kBgr888:
            case camera::PixelFormat::kXrgb8888:
            case camera::PixelFormat::kXbgr8888:
                wanted = {options_.pixel_format};
                break;
            case camera::PixelFormat::kMjpeg:
            case camera::PixelFormat::kGrey:
                return error(ErrorCode::kInvalidArgument,
                             std::string("pixel format ") + toString(options_.pixel_format) +
                                 " is not supported by the libcamera driver (use auto, YUYV, "
                                 "NV12, YUV420, RGB888, BGR888, XRGB8888 or XBGR8888)");
        }
        return wanted;
    }

    // Configures the camera with `candidate` (libcamera's `format`) at `asked`:
    // true when configured, false when the camera rejects it (the reason
    // appended to `rejected`).
    core::Result<bool> configureFormat(camera::PixelFormat candidate,
                                       const libcamera::PixelFormat& format,
                                       const libcamera::Size& asked, std::string& rejected) {
        // A fresh configuration per candidate: validate() edits it.
        auto config = generateStreamConfiguration(*camera_);
        if (!config) {
            return error(ErrorCode::kNotFound, "offers no viewfinder or video stream");
        }
        libcamera::StreamConfiguration& stream = config->at(0);
        stream.pixelFormat = format;
        stream.size = asked;
        stream.bufferCount = static_cast<unsigned>(options_.buffers);
        if (config->validate() == libcamera::CameraConfiguration::Invalid) {
            rejected +=
                std::string(rejected.empty() ? "" : ", ") + toString(candidate) + " (invalid)";
            return false;
        }
        const auto raw = scaledFormat(stream.pixelFormat);
        if (!raw) {
            rejected += std::string(rejected.empty() ? "" : ", ") + toString(candidate) +
                        " (became " + stream.pixelFormat.toString() + ")";
            return false;
        }
        if (stream.size != asked) {
            session_notes_.push_back(describe() + ": asked for " + sizeText(asked) +
                                     ", the camera gives " + sizeText(stream.size) + " (used)");
        }
        if (stream.bufferCount != static_cast<unsigned>(options_.buffers)) {
            session_notes_.push_back(
                describe() + ": asked for " + std::to_string(options_.buffers) +
                " buffers, the camera uses " + std::to_string(stream.bufferCount));
        }
        const int rc = camera_->configure(config.get());
        if (rc < 0) {
            return libcameraError("cannot configure " + stream.toString(), rc);
        }
        stream_ = stream.stream();
        if (stream_ == nullptr) {
            return error(ErrorCode::kIo, "configured without a stream");
        }
        format_ = *raw;
        width_px_ = static_cast<int>(stream.size.width);
        height_px_ = static_cast<int>(stream.size.height);
        stride_bytes_ = stream.stride;
        config_ = std::move(config);
        return true;
    }

    // None of `wanted` could be configured at `asked`: what was offered and why.
    core::Error noUsableFormatError(const std::vector<camera::PixelFormat>& wanted,
                                    const libcamera::Size& asked, const std::string& offered_text,
                                    const std::string& rejected) const {
        std::string scaled_formats;
        for (const camera::PixelFormat f : wanted) {
            scaled_formats += std::string(scaled_formats.empty() ? "" : ", ") + toString(f);
        }
        return error(ErrorCode::kInvalidArgument,
                     "no usable pixel format at " + sizeText(asked) + " (the stream offers " +
                         (offered_text.empty() ? std::string("none") : offered_text) +
                         "; scaled converts " + scaled_formats +
                         (rejected.empty() ? std::string() : "; rejected: " + rejected) + ")");
    }

    // Chooses the pixel format and validates the size; configures the camera.
    core::Status configureStream() {
        auto wanted = wantedFormats();
        if (!wanted) {
            return wanted.error();
        }
        auto probe = generateStreamConfiguration(*camera_);
        if (!probe) {
            return error(ErrorCode::kNotFound, "offers no viewfinder or video stream");
        }
        const std::vector<libcamera::PixelFormat> offered = probe->at(0).formats().pixelformats();
        std::string offered_text;
        for (const auto& format : offered) {
            offered_text += (offered_text.empty() ? "" : ", ") + format.toString();
        }
        const libcamera::Size asked(static_cast<unsigned>(options_.width_px),
                                    static_cast<unsigned>(options_.height_px));
        std::string rejected;
        for (const camera::PixelFormat candidate : *wanted) {
            const libcamera::PixelFormat format = libcameraFormat(candidate);
            if (!offered.empty() &&
                std::find(offered.begin(), offered.end(), format) == offered.end()) {
                continue;
            }
            auto configured = configureFormat(candidate, format, asked, rejected);
            if (!configured) {
                return configured.error();
            }
            if (*configured) {
                return {};
            }
        }
        return noUsableFormatError(*wanted, asked, offered_text, rejected);
    }

    // Buffers from libcamera's allocator, each mapped once, one request each.
    core::Status allocateBuffers() {
        allocator_ = std::make_unique<libcamera::FrameBufferAllocator>(camera_);
        const int count = allocator_->allocate(stream_);
        if (count < 0) {
            return libcameraError("cannot allocate buffers", count);
        }
        const auto& buffers = allocator_->buffers(stream_);
        if (count == 0 || buffers.empty()) {
            return error(ErrorCode::kIo, "the allocator gave no buffers");
        }
        const std::size_t used =
            std::min(buffers.size(), static_cast<std::size_t>(options_.buffers));
        for (std::size_t i = 0; i < used; ++i) {
            auto mapped = mapBuffer(*buffers[i]);
            if (!mapped) {
                return mapped.error();
            }
            views_.push_back(*mapped);
            // Built once: convertRawImage() names the buffer in its errors.
            buffer_names_.push_back(describe() + ": buffer " + std::to_string(i));
            std::unique_ptr<libcamera::Request> request = camera_->createRequest(i);
            if (!request) {
                return error(ErrorCode::kIo, "cannot create a request");
            }
            const int added = request->addBuffer(stream_, buffers[i].get());
            if (added < 0) {
                return libcameraError("cannot add a buffer to a request", added);
            }
            requests_.push_back(std::move(request));
        }
        const std::lock_guard lock(mutex_);
        completed_.assign(requests_.size(), nullptr);
        return {};
    }

    // Maps each dmabuf of `buffer` once (planes of one buffer often share
    // one dmabuf at different offsets) and lays the format's planes out.
    core::Result<camera::RawImage> mapBuffer(const libcamera::FrameBuffer& buffer) {
        std::map<int, std::size_t> extent;  // fd -> bytes the planes use
        for (const auto& plane : buffer.planes()) {
            const int fd = plane.fd.get();
            if (fd < 0) {
                return error(ErrorCode::kIo, "a buffer plane has no file descriptor");
            }
            const std::size_t end =
                static_cast<std::size_t>(plane.offset) + static_cast<std::size_t>(plane.length);
            extent[fd] = std::max(extent[fd], end);
        }
        std::map<int, const std::uint8_t*> base;
        for (const auto& [fd, length] : extent) {
            void* address = ::mmap(nullptr, length, PROT_READ, MAP_SHARED, fd, 0);
            if (address == MAP_FAILED) {
                return error(ErrorCode::kIo, "cannot map a buffer of " + std::to_string(length) +
                                                 " bytes: " + errnoText(errno));
            }
            mappings_.push_back({address, length});
            base[fd] = static_cast<const std::uint8_t*>(address);
        }
        // At most one plane per format plane (three): a fixed array.
        std::array<libcam::BufferPlane, 3> planes{};
        const std::size_t count = buffer.planes().size();
        if (count > planes.size()) {
            return error(ErrorCode::kInvalidArgument, std::string(toString(format_)) +
                                                          ": the buffer has " +
                                                          std::to_string(count) + " planes");
        }
        for (std::size_t i = 0; i < count; ++i) {
            const auto& plane = buffer.planes()[i];
            planes.at(i) = {base[plane.fd.get()] + plane.offset, plane.length};
        }
        auto raw = libcam::describeBuffer(format_, width_px_, height_px_, stride_bytes_,
                                          std::span(planes.data(), count));
        if (!raw) {
            return error(raw.error().code, raw.error().message);
        }
        return raw;
    }

    // FrameDurationLimits = 1 / fps when the camera has the control (clamped
    // to its range). Returns the frame rate set, 0 when it could not be set.
    double frameRateControl(libcamera::ControlList& controls) {
        const libcamera::ControlInfoMap& infos = camera_->controls();
        const auto it = infos.find(libcamera::controls::FrameDurationLimits.id());
        if (it == infos.end()) {
            session_notes_.push_back(describe() +
                                     ": no frame-rate control (FrameDurationLimits); the camera "
                                     "runs at its own rate, not " +
                                     fpsText(options_.fps) + " fps");
            return 0;
        }
        int64_t duration_us = std::llround(1e6 / options_.fps);
        const libcamera::ControlInfo& info = it->second;
        const auto bound = [](const libcamera::ControlValue& value) -> std::optional<int64_t> {
            if (value.type() != libcamera::ControlTypeInteger64 || value.isArray()) {
                return std::nullopt;
            }
            return value.get<int64_t>();
        };
        const auto lo = bound(info.min());
        const auto hi = bound(info.max());
        const int64_t wanted_us = duration_us;
        if (lo && *lo > 0 && duration_us < *lo) {
            duration_us = *lo;
        }
        if (hi && *hi > 0 && duration_us > *hi) {
            duration_us = *hi;
        }
        const double fps = 1e6 / static_cast<double>(duration_us);
        if (duration_us != wanted_us) {
            session_notes_.push_back(
                describe() + ": asked for " + fpsText(options_.fps) + " fps, the camera allows " +
                fpsText(hi ? 1e6 / static_cast<double>(*hi) : 0.0) + " to " +
                fpsText(lo ? 1e6 / static_cast<double>(*lo) : 0.0) + " fps; using " + fpsText(fps));
        }
        std::array<int64_t, 2> limits{duration_us, duration_us};
        controls.set(libcamera::controls::FrameDurationLimits,
                     libcamera::Span<const int64_t, 2>(limits));
        return fps;
    }

    // Converts the completed `request` into `frame` and requeues it.
    // true: a frame; false: a cancelled request (nothing to deliver);
    // kUnavailable: the camera could not take the request back (closed);
    // other errors: one bad frame.
    core::Result<bool> deliver(libcamera::Request* request, source::Frame& frame) {
        const bool cancelled = request->status() == libcamera::Request::RequestCancelled;
        core::Status converted;
        int64_t t_ns = 0;
        if (!cancelled) {
            // Converted before the buffer goes back to the camera.
            converted = convert(*request, frame.gray, frame.color, t_ns);
        }
        request->reuse(libcamera::Request::ReuseBuffers);
        const int queued = camera_->queueRequest(request);
        if (queued < 0) {
            closeSession();
            return error(ErrorCode::kUnavailable, (queued == -ENODEV ? std::string("device lost")
                                                                     : "cannot queue a request") +
                                                      ": " + errnoText(-queued));
        }
        if (cancelled) {
            return false;
        }
        if (!converted) {
            return converted.error();
        }
        if (t_ns <= last_t_ns_) {
            t_ns = last_t_ns_ + 1;  // keep the contract's strict order
        }
        last_t_ns_ = t_ns;
        // The rest of the Frame in place too (a new Frame would drop the Mats
        // the pixels were just written into).
        frame.id = delivered_++;
        frame.t_ns = t_ns;
        frame.T_CtoW_gt.reset();
        frame.depth_path.reset();
        frame.image_path.clear();
        frame.gravity_down_C.reset();
        frame.accel_C.reset();
        return true;
    }

    core::Status convert(libcamera::Request& request, cv::Mat& gray, cv::Mat& bgr, int64_t& t_ns) {
        const libcamera::FrameBuffer* buffer = request.findBuffer(stream_);
        const uint64_t index = request.cookie();
        if (buffer == nullptr || index >= views_.size()) {
            return error(ErrorCode::kIo, "a completed request without its buffer");
        }
        const libcamera::FrameMetadata& metadata = buffer->metadata();
        if (metadata.status != libcamera::FrameMetadata::FrameSuccess) {
            return error(ErrorCode::kIo, "the camera reported a bad frame (sequence " +
                                             std::to_string(metadata.sequence) + ")");
        }
        // Into the caller's Mats, in place: no allocation once they have the
        // size (the pipeline hands the same Frames back).
        auto converted = camera::convertRawImage(views_[index], buffer_names_[index], gray, bgr);
        if (!converted) {
            return converted.error();
        }
        // The sensor's start of exposure; the pipelines take it from the
        // V4L2 buffer, CLOCK_MONOTONIC. Fall back to the buffer's own time.
        const auto sensor = request.metadata().get(libcamera::controls::SensorTimestamp);
        t_ns = sensor ? *sensor : 0;
        if (t_ns <= 0) {
            t_ns = static_cast<int64_t>(metadata.timestamp);
        }
        if (t_ns <= 0) {
            t_ns = monotonicNowNs();
        }
        return {};
    }

    // libcamera's thread: hand the request to next().
    void onRequestCompleted(libcamera::Request* request) {
        {
            const std::lock_guard lock(mutex_);
            // Never full: each request is queued at most once and there are
            // completed_.size() of them.
            if (queued_ < completed_.size()) {
                completed_[(head_ + queued_) % completed_.size()] = request;
                ++queued_;
            }
        }
        cv_.notify_all();
    }

    // libcamera's thread: the camera went away (unplugged, driver unloaded).
    void onDisconnected() {
        {
            const std::lock_guard lock(mutex_);
            disconnected_ = true;
        }
        cv_.notify_all();
    }

    // Undoes startSession() in libcamera's order: stop, requests, buffers,
    // release, the camera. Safe on a partly opened session.
    void closeSession() {
        bool was_disconnected = false;
        {
            const std::lock_guard lock(mutex_);
            was_disconnected = disconnected_;
        }
        bool leak = false;
        if (camera_ && started_) {
            // Completes every queued request (cancelled) before it returns.
            // Not so on a disconnected camera: libcamera then returns at once
            // (or fails) and requests may still be in flight inside it; they
            // and their buffers are kept (leaked) rather than freed under it.
            leak = camera_->stop() < 0 || was_disconnected;
            started_ = false;
        }
        if (camera_ && connected_) {
            camera_->requestCompleted.disconnect(this);
            camera_->disconnected.disconnect(this);
            connected_ = false;
        }
        {
            const std::lock_guard lock(mutex_);
            head_ = 0;
            queued_ = 0;
        }
        for (const Mapping& mapping : mappings_) {
            ::munmap(mapping.address, mapping.length);
        }
        mappings_.clear();
        views_.clear();
        buffer_names_.clear();
        if (leak) {
            bury(std::make_shared<decltype(requests_)>(std::move(requests_)));
            bury(std::shared_ptr<libcamera::FrameBufferAllocator>(std::move(allocator_)));
        }
        requests_.clear();
        allocator_.reset();
        config_.reset();
        stream_ = nullptr;
        if (camera_ && acquired_) {
            camera_->release();  // fails only when not acquired: nothing to undo
            acquired_ = false;
        }
        camera_.reset();
    }

    camera::CameraOptions options_;
    std::shared_ptr<libcamera::CameraManager> manager_;
    std::string id_;
    source::SequenceInfo info_;
    std::vector<std::string> session_notes_;

    // The session (capture thread only).
    std::shared_ptr<libcamera::Camera> camera_;
    bool acquired_ = false;
    bool connected_ = false;
    bool started_ = false;
    std::unique_ptr<libcamera::CameraConfiguration> config_;
    libcamera::Stream* stream_ = nullptr;
    std::unique_ptr<libcamera::FrameBufferAllocator> allocator_;
    std::vector<std::unique_ptr<libcamera::Request>> requests_;
    std::vector<Mapping> mappings_;
    std::vector<camera::RawImage> views_;    // the buffers' images, by request cookie
    std::vector<std::string> buffer_names_;  // "<camera>: buffer <i>", by request cookie
    camera::PixelFormat format_ = camera::PixelFormat::kYuyv;
    int width_px_ = 0;
    int height_px_ = 0;
    std::size_t stride_bytes_ = 0;
    int first_width_px_ = 0;
    int first_height_px_ = 0;
    int64_t delivered_ = 0;
    int64_t last_t_ns_ = 0;

    // Shared with libcamera's thread and stop().
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::vector<libcamera::Request*> completed_;  // ring of completed requests
    std::size_t head_ = 0;
    std::size_t queued_ = 0;
    bool stopped_ = false;
    bool disconnected_ = false;
    std::string mode_;
};

core::Status checkOptions(const camera::CameraOptions& options, const std::string& who) {
    const auto bad = [&](const std::string& what) {
        return makeError(ErrorCode::kInvalidArgument, who + ": " + what);
    };
    if (options.width_px <= 0 || options.height_px <= 0 || options.width_px > 65535 ||
        options.height_px > 65535) {
        return bad("invalid size " + std::to_string(options.width_px) + "x" +
                   std::to_string(options.height_px));
    }
    if (!std::isfinite(options.fps) || options.fps <= 0 || options.fps > 1000) {
        return bad("frame rate must be in (0, 1000] fps, not " + fpsText(options.fps));
    }
    if (options.buffers < 2 || options.buffers > 32) {
        return bad("buffers must be 2..32, not " + std::to_string(options.buffers));
    }
    if (!std::isfinite(options.frame_timeout_s) || options.frame_timeout_s <= 0 ||
        options.frame_timeout_s > 3600) {
        return bad("frame timeout must be in (0, 3600] s, not " + fpsText(options.frame_timeout_s));
    }
    return {};
}

}  // namespace

bool libcameraAvailable() {
    return true;
}

core::Result<std::unique_ptr<camera::LiveCamera>> openLibcameraCamera(
    const camera::CameraOptions& options) {
    const std::string who = "libcamera camera " + quoted(options.device);
    auto valid = checkOptions(options, who);
    if (!valid) {
        return valid.error();
    }
    auto manager = sharedManager();
    if (!manager) {
        return makeError(manager.error().code, who + ": " + manager.error().message);
    }
    std::string id;
    {
        auto found = findCamera(**manager, options.device);
        if (!found) {
            return found.error();
        }
        id = (*found)->id();
    }
    auto camera = std::make_unique<LibcameraCamera>(options, std::move(*manager), id);
    auto opened = camera->open();
    if (!opened) {
        return opened.error();
    }
    return std::unique_ptr<camera::LiveCamera>(std::move(camera));
}

std::vector<camera::CameraDescription> listLibcameraCameras() {
    auto manager = sharedManager();
    if (!manager) {
        return {};
    }
    std::vector<camera::CameraDescription> out;
    // Declared after the manager: destroyed (cameras released) before it.
    const std::vector<std::shared_ptr<libcamera::Camera>> cameras = (*manager)->cameras();
    for (const auto& camera : cameras) {
        camera::CameraDescription desc;
        desc.backend = "libcamera";
        desc.device = camera->id();
        desc.name = modelOf(*camera);
        if (desc.name.empty()) {
            desc.name = camera->id();
        }
        desc.bus = locationOf(*camera);
        const auto config = generateStreamConfiguration(*camera);
        if (!config) {
            desc.note = "no viewfinder or video stream";
        } else {
            const libcamera::StreamFormats& formats = config->at(0).formats();
            std::string unusable;
            for (const libcamera::PixelFormat& format : formats.pixelformats()) {
                if (!scaledFormat(format)) {
                    unusable += (unusable.empty() ? "" : ", ") + format.toString();
                    continue;
                }
                const std::vector<libcamera::Size> sizes = formats.sizes(format);
                for (const libcamera::Size& size : sizes) {
                    desc.formats.push_back(format.toString() + " " + sizeText(size));
                }
                if (sizes.empty()) {
                    const libcamera::SizeRange range = formats.range(format);
                    desc.formats.push_back(format.toString() + " " + sizeText(range.min) + "-" +
                                           sizeText(range.max));
                }
            }
            if (desc.formats.empty()) {
                desc.note = "no format scaled converts (offers " +
                            (unusable.empty() ? std::string("none") : unusable) + ")";
            }
        }
        // Busy: another process (or an open source of this one) holds it.
        const int acquired = camera->acquire();
        if (acquired == -EBUSY) {
            desc.note += std::string(desc.note.empty() ? "" : "; ") + "busy";
        } else if (acquired == 0) {
            camera->release();
        }
        out.push_back(std::move(desc));
    }
    return out;
}

}  // namespace scaled::drivers::libcam
