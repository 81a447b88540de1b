#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <exception>
#include <fstream>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>

#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/detector/thread_priority.h>
#include <scaled/drivers/detector/yolo_decode.h>

namespace scaled::drivers::detector {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Scalar;
using core::Status;

namespace {

constexpr int kInputMultiple = 32;
constexpr std::size_t kMaxClassNames = 10000;
constexpr std::uintmax_t kMaxNamesBytes = std::uintmax_t{1} << 20U;
constexpr int kBoxColumns = 5;  // cx, cy, w, h, objectness
constexpr double kYoloxPad = 114;
constexpr std::size_t kMaxShownChars = 200;

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The first line of an OpenCV error, shortened: enough to say what failed.
std::string openCvReason(const cv::Exception& e) {
    std::string msg = e.err.empty() ? e.msg : e.err;
    if (const std::size_t nl = msg.find('\n'); nl != std::string::npos) {
        msg.resize(nl);
    }
    if (msg.size() > kMaxShownChars) {
        msg.resize(kMaxShownChars);
        msg += "...";
    }
    return msg;
}

std::string fieldError(std::string_view field, const std::string& value, std::string_view rule) {
    return "detector config: " + std::string(field) + " = " + value + ": " + std::string(rule);
}

std::string floatText(float v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

Status checkReadableFile(const std::filesystem::path& path, std::string_view what) {
    std::error_code ec;
    if (path.empty()) {
        return makeError(ErrorCode::kInvalidArgument, std::string(what) + " path is empty");
    }
    if (!std::filesystem::is_regular_file(path, ec) || ec) {
        return makeError(ErrorCode::kNotFound,
                         path.string() + ": " + std::string(what) + " not found");
    }
    const std::uintmax_t size = std::filesystem::file_size(path, ec);
    if (ec) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot read " + std::string(what) +
                                             " (" + ec.message() + ")");
    }
    if (size == 0) {
        return makeError(ErrorCode::kParse, path.string() + ": " + std::string(what) + " is empty");
    }
    std::ifstream probe(path, std::ios::binary);
    if (!probe) {
        return makeError(ErrorCode::kIo,
                         path.string() + ": cannot open " + std::string(what) + " for reading");
    }
    return {};
}

// OpenCV's Darknet importer reads the weights without checking their length:
// a truncated file loads silently with zeros. The weights file holds a header
// (major, minor, revision as int32, then `seen` as int64 from version 0.2 on,
// int32 before) and one float32 per parameter of the convolution and batch
// norm layers, which is exactly what the imported layers hold (the region
// layers' anchors come from the cfg).
Status checkDarknetWeightsSize(cv::dnn::Net& net, const std::filesystem::path& weights) {
    std::ifstream in(weights, std::ios::binary);
    std::array<std::int32_t, 3> version{};
    if (!in.read(reinterpret_cast<char*>(version.data()), sizeof version)) {
        return makeError(ErrorCode::kParse,
                         weights.string() + ": Darknet weights file shorter than its header");
    }
    const std::uintmax_t header =
        sizeof version +
        ((version[0] * 10 + version[1]) >= 2 ? sizeof(std::int64_t) : sizeof(std::int32_t));
    std::error_code ec;
    const std::uintmax_t bytes = std::filesystem::file_size(weights, ec);
    std::size_t needed = 0;
    for (const cv::String& name : net.getLayerNames()) {
        const cv::Ptr<cv::dnn::Layer> layer = net.getLayer(name);
        if (layer->type == "Region") {
            continue;
        }
        for (const cv::Mat& blob : layer->blobs) {
            needed += blob.total();
        }
    }
    const std::uintmax_t needed_bytes = header + needed * sizeof(float);
    if (ec || bytes != needed_bytes) {
        return makeError(
            ErrorCode::kParse,
            weights.string() + ": Darknet weights file has " + std::to_string(bytes) +
                " bytes but its cfg needs " + std::to_string(needed_bytes) +
                (bytes < needed_bytes ? " (truncated?)" : " (weights of another cfg?)"));
    }
    return {};
}

}  // namespace

const char* toString(ModelFamily family) {
    switch (family) {
        case ModelFamily::kYolox:
            return "yolox";
        case ModelFamily::kDarknet:
            return "darknet";
    }
    return "?";
}

Result<ModelFamily> parseModelFamily(std::string_view text) {
    if (text == "yolox") {
        return ModelFamily::kYolox;
    }
    if (text == "darknet") {
        return ModelFamily::kDarknet;
    }
    return makeError(ErrorCode::kInvalidArgument,
                     "unknown model family '" + std::string(text) + "' (yolox or darknet)");
}

ModelFamily familyFromPath(const std::filesystem::path& model_path) {
    std::string ext = model_path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return ext == ".cfg" ? ModelFamily::kDarknet : ModelFamily::kYolox;
}

Status validate(const DetectorConfig& config) {
    using L = DetectorLimits;
    const int s = config.input_size_px;
    if (!L::input_size_px.contains(s) || s % kInputMultiple != 0) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("input_size_px", std::to_string(s),
                                    "must be a multiple of 32 " + L::input_size_px.text()));
    }
    if (!L::score_threshold.contains(static_cast<double>(config.score_threshold))) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("score_threshold", floatText(config.score_threshold),
                                    "must be " + L::score_threshold.text()));
    }
    if (!L::nms_iou_threshold.contains(static_cast<double>(config.nms_iou_threshold))) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("nms_iou_threshold", floatText(config.nms_iou_threshold),
                                    "must be " + L::nms_iou_threshold.text()));
    }
    if (!L::threads.contains(config.threads)) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("threads", std::to_string(config.threads),
                                    "must be " + L::threads.text() + " (0: OpenCV's default)"));
    }
    if (!L::nice.contains(config.nice)) {
        return makeError(
            ErrorCode::kInvalidArgument,
            fieldError("nice", std::to_string(config.nice), "must be " + L::nice.text()));
    }
    if (!L::max_detections.contains(config.max_detections)) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("max_detections", std::to_string(config.max_detections),
                                    "must be " + L::max_detections.text()));
    }
    for (const std::string& name : config.classes) {
        if (name.empty()) {
            return makeError(ErrorCode::kInvalidArgument,
                             fieldError("classes", "\"\"", "class names must not be empty"));
        }
    }
    if (config.model_path.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         fieldError("model_path", "\"\"", "a model file is required"));
    }
    return {};
}

Result<std::vector<std::string>> readClassNames(const std::filesystem::path& names_file) {
    if (auto ok = checkReadableFile(names_file, "class names file"); !ok) {
        return ok.error();
    }
    std::error_code ec;
    if (std::filesystem::file_size(names_file, ec) > kMaxNamesBytes) {
        return makeError(ErrorCode::kParse, names_file.string() +
                                                ": class names file larger than 1 MiB (not "
                                                "a names file?)");
    }
    std::ifstream in(names_file, std::ios::binary);
    std::vector<std::string> names;
    std::string line;
    std::size_t number = 0;
    std::size_t blank_line = 0;
    while (std::getline(in, line)) {
        ++number;
        if (!line.empty() && line.back() == '\r') {
            line.pop_back();
        }
        if (line.empty()) {
            if (blank_line == 0) {
                blank_line = number;
            }
            continue;
        }
        if (blank_line != 0) {
            return makeError(ErrorCode::kParse,
                             names_file.string() + ":" + std::to_string(blank_line) +
                                 ": empty class name (class ids follow line order, so a blank "
                                 "line would shift them)");
        }
        for (const char c : line) {
            if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
                return makeError(ErrorCode::kParse, names_file.string() + ":" +
                                                        std::to_string(number) +
                                                        ": control character in class name");
            }
        }
        names.push_back(line);
        if (names.size() > kMaxClassNames) {
            return makeError(ErrorCode::kParse,
                             names_file.string() + ": more than 10000 class names");
        }
    }
    if (in.bad()) {
        return makeError(ErrorCode::kIo, names_file.string() + ": read error");
    }
    if (names.empty()) {
        return makeError(ErrorCode::kParse, names_file.string() + ": no class names");
    }
    return names;
}

struct DnnDetector::Impl {
    DetectorConfig config;
    DetectorInfo info;
    std::vector<std::string> names;
    cv::dnn::Net net;
    std::vector<cv::String> out_names;
    std::vector<cv::Mat> outs;
    std::vector<YoloxCell> grid;  // kYolox: one per output row
    std::optional<YoloDecoder> decoder;
    // Per-frame buffers, reused.
    cv::Mat bgr;
    cv::Mat resized;
    cv::Mat canvas;
    cv::Mat blob;

    void applyThreads() const {
        if (config.threads > 0 && cv::getNumThreads() != config.threads) {
            cv::setNumThreads(config.threads);
        }
    }

    // Fills `blob` from an 8-bit gray, BGR or BGRA image; returns the YOLOX
    // letterbox ratio (network pixels per image pixel; 1 for Darknet, whose
    // boxes are fractions of the image).
    double preprocess(const cv::Mat& image);
    void forward();

    // The steps of create(); `what` names the model's files in messages.
    // Reads the network (OpenCV exceptions caught here), checks Darknet weights.
    core::Status loadNet(const std::string& what);
    // One forward pass on a blank image at the configured size.
    core::Status warmUp(const std::string& what);
    // The outputs' shape against the class names (and YOLOX's grid, made
    // here); the number of rows (boxes) in all outputs.
    core::Result<std::size_t> checkOutputs(const std::string& what);
};

double DnnDetector::Impl::preprocess(const cv::Mat& image) {
    const int s = config.input_size_px;
    const cv::Mat* src = &image;
    if (image.channels() == 1) {
        cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
        src = &bgr;
    } else if (image.channels() == 4) {
        cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
        src = &bgr;
    }
    if (config.family == ModelFamily::kDarknet) {
        cv::dnn::blobFromImage(*src, blob, 1.0 / 255.0, cv::Size(s, s), cv::Scalar(), true, false,
                               CV_32F);
        return 1;
    }
    const double ratio =
        std::min(static_cast<double>(s) / src->rows, static_cast<double>(s) / src->cols);
    const int w = std::clamp(static_cast<int>(src->cols * ratio), 1, s);
    const int h = std::clamp(static_cast<int>(src->rows * ratio), 1, s);
    cv::resize(*src, resized, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);
    canvas.create(s, s, CV_8UC3);
    canvas.setTo(cv::Scalar::all(kYoloxPad));
    resized.copyTo(canvas(cv::Rect(0, 0, w, h)));
    cv::dnn::blobFromImage(canvas, blob, 1.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    return ratio;
}

void DnnDetector::Impl::forward() {
    applyThreads();
    net.setInput(blob);
    net.forward(outs, out_names);
}

DnnDetector::DnnDetector(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
DnnDetector::~DnnDetector() = default;

const DetectorInfo& DnnDetector::info() const {
    return impl_->info;
}

const DetectorConfig& DnnDetector::config() const {
    return impl_->config;
}

std::span<const std::string> DnnDetector::classNames() const {
    return impl_->names;
}

namespace {

// The paths of the model, weights and class names `config` names (or implies).
void fillModelPaths(const DetectorConfig& config, DetectorInfo& info) {
    info.family = config.family;
    info.model_path = config.model_path;
    info.input_size_px = config.input_size_px;
    info.names_path = config.names_path.empty() ? config.model_path.parent_path() / "coco.names"
                                                : config.names_path;
    if (config.family == ModelFamily::kDarknet) {
        info.weights_path =
            config.weights_path.empty()
                ? std::filesystem::path(config.model_path).replace_extension(".weights")
                : config.weights_path;
    }
}

core::Status checkModelFiles(const DetectorInfo& info, bool darknet) {
    if (auto ok = checkReadableFile(info.model_path, darknet ? "Darknet cfg file" : "ONNX model");
        !ok) {
        return ok.error();
    }
    if (darknet) {
        if (auto ok = checkReadableFile(info.weights_path, "Darknet weights file"); !ok) {
            return ok.error();
        }
    }
    return {};
}

// Per class name, 1 when its detections are kept (config.classes; all when empty).
Result<std::vector<unsigned char>> allowedClasses(const std::vector<std::string>& names,
                                                  const DetectorConfig& config,
                                                  const std::filesystem::path& names_path) {
    std::vector<unsigned char> allowed(names.size(), config.classes.empty() ? 1 : 0);
    for (const std::string& wanted : config.classes) {
        const auto it = std::find(names.begin(), names.end(), wanted);
        if (it == names.end()) {
            return makeError(ErrorCode::kInvalidArgument,
                             fieldError("classes", "\"" + wanted + "\"",
                                        "not a class of " + names_path.string()));
        }
        allowed[static_cast<std::size_t>(it - names.begin())] = 1;
    }
    return allowed;
}

}  // namespace

core::Status DnnDetector::Impl::loadNet(const std::string& what) {
    const bool darknet = config.family == ModelFamily::kDarknet;
    try {
        net = darknet ? cv::dnn::readNetFromDarknet(info.model_path.string(),
                                                    info.weights_path.string())
                      : cv::dnn::readNetFromONNX(info.model_path.string());
    } catch (const cv::Exception& e) {
        return makeError(ErrorCode::kParse, what + ": cannot load the " +
                                                std::string(toString(config.family)) +
                                                " model (OpenCV: " + openCvReason(e) + ")");
    }
    if (net.empty()) {
        return makeError(ErrorCode::kParse, what + ": the " + std::string(toString(config.family)) +
                                                " model has no layers");
    }
    if (darknet) {
        if (auto ok = checkDarknetWeightsSize(net, info.weights_path); !ok) {
            return ok.error();
        }
    }
    return {};
}

core::Status DnnDetector::Impl::warmUp(const std::string& what) {
    const int s = config.input_size_px;
    try {
        net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
        net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
        out_names = net.getUnconnectedOutLayersNames();
        const cv::Mat blank(s, s, CV_8UC3, cv::Scalar::all(kYoloxPad));
        (void)preprocess(blank);
        forward();
    } catch (const cv::Exception& e) {
        return makeError(ErrorCode::kParse, what + ": the model does not run at input size " +
                                                std::to_string(s) + " (OpenCV: " + openCvReason(e) +
                                                ")");
    }
    return {};
}

Result<std::size_t> DnnDetector::Impl::checkOutputs(const std::string& what) {
    const bool darknet = config.family == ModelFamily::kDarknet;
    const int s = config.input_size_px;
    const int cols = kBoxColumns + info.class_count;
    if (outs.empty()) {
        return makeError(ErrorCode::kParse, what + ": the model has no outputs");
    }
    std::size_t rows = 0;
    for (const cv::Mat& out : outs) {
        const int out_cols = out.dims >= 2 ? out.size[out.dims - 1] : 0;
        if (out_cols != cols) {
            return makeError(ErrorCode::kParse, what + ": the model outputs " +
                                                    std::to_string(out_cols - kBoxColumns) +
                                                    " classes per box but " +
                                                    info.names_path.string() + " names " +
                                                    std::to_string(info.class_count));
        }
        if (out.type() != CV_32F) {
            return makeError(ErrorCode::kParse, what + ": the model output is not float32");
        }
        // cols > kBoxColumns: create() reads at least one class name before this.
        // NOLINTNEXTLINE(clang-analyzer-core.DivideZero)
        rows += out.total() / static_cast<std::size_t>(cols);
    }
    if (!darknet) {
        grid = makeYoloxGrid(s);
        if (outs.size() != 1 || rows != grid.size()) {
            return makeError(ErrorCode::kParse,
                             what + ": expected one output of " + std::to_string(grid.size()) +
                                 " rows at input size " + std::to_string(s) +
                                 " (YOLOX strides 8, 16, 32), got " + std::to_string(outs.size()) +
                                 " output(s) of " + std::to_string(rows) + " rows in total");
        }
    }
    return rows;
}

Result<std::unique_ptr<DnnDetector>> DnnDetector::create(const DetectorConfig& config) {
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    DetectorInfo& info = impl->info;
    fillModelPaths(config, info);
    const bool darknet = config.family == ModelFamily::kDarknet;

    if (auto ok = checkModelFiles(info, darknet); !ok) {
        return ok.error();
    }
    auto names = readClassNames(info.names_path);
    if (!names) {
        return names.error();
    }
    impl->names = std::move(*names);
    info.class_count = static_cast<int>(impl->names.size());
    auto allowed = allowedClasses(impl->names, config, info.names_path);
    if (!allowed) {
        return allowed.error();
    }

    const std::string what = darknet ? info.model_path.string() + " + " + info.weights_path.string()
                                     : info.model_path.string();
    if (auto ok = impl->loadNet(what); !ok) {
        return ok.error();
    }
    // Warm-up at the configured size: checks that the network runs there and
    // outputs what the decoder expects, and pays first-run costs now.
    if (auto ok = impl->warmUp(what); !ok) {
        return ok.error();
    }
    auto rows = impl->checkOutputs(what);
    if (!rows) {
        return rows.error();
    }
    impl->decoder.emplace(std::move(*allowed), *rows);
    return std::unique_ptr<DnnDetector>(new DnnDetector(std::move(impl)));
}

Status DnnDetector::detect(const cv::Mat& image, std::int64_t frame_id, std::int64_t t_ns,
                           DetectionResult& out) {
    out.frame_id = frame_id;
    out.t_ns = t_ns;
    out.width_px = image.cols;
    out.height_px = image.rows;
    out.detections.clear();
    out.timing = {};
    if (image.empty() || image.depth() != CV_8U ||
        (image.channels() != 1 && image.channels() != 3 && image.channels() != 4) ||
        image.dims != 2) {
        return makeError(
            ErrorCode::kInvalidArgument,
            "detect: expected a non-empty 8-bit image with 1, 3 or 4 channels (frame " +
                std::to_string(frame_id) + ")");
    }
    Impl& m = *impl_;
    YoloDecoder& decoder = *m.decoder;
    decoder.clear();
    try {
        auto t0 = Clock::now();
        const double ratio = m.preprocess(image);
        out.timing.pre_ms = msSince(t0);
        t0 = Clock::now();
        m.forward();
        out.timing.forward_ms = msSince(t0);
        t0 = Clock::now();
        const DetectorConfig& c = m.config;
        if (c.family == ModelFamily::kYolox) {
            decoder.addYolox(reinterpret_cast<const float*>(m.outs.front().data), m.grid, ratio,
                             c.score_threshold);
        } else {
            const auto cols = static_cast<std::size_t>(kBoxColumns) +
                              static_cast<std::size_t>(m.info.class_count);
            for (const cv::Mat& o : m.outs) {
                decoder.addDarknet(reinterpret_cast<const float*>(o.data), o.total() / cols,
                                   image.cols, image.rows, c.score_threshold);
            }
        }
        decoder.finish(m.names, c.score_threshold, c.nms_iou_threshold, c.max_detections, out);
        out.timing.post_ms = msSince(t0);
    } catch (const cv::Exception& e) {
        out.detections.clear();
        return makeError(ErrorCode::kIo, "detect: " + m.info.model_path.string() +
                                             " failed on frame " + std::to_string(frame_id) +
                                             " (OpenCV: " + openCvReason(e) + ")");
    }
    return {};
}

std::size_t toEstimatorDetections(const DetectionResult& result, std::span<core::Detection> out) {
    const std::size_t n = std::min(out.size(), result.detections.size());
    for (std::size_t i = 0; i < n; ++i) {
        const ObjectDetection& d = result.detections[i];
        out[i].box = d.box;
        out[i].class_name = d.class_name;
        out[i].score = static_cast<Scalar>(d.score);
    }
    return n;
}

}  // namespace scaled::drivers::detector
