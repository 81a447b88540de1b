// The OpenCV DNN detector: configuration and file errors, and the real models
// of ../shared/models on real frames of ../shared/data (skipped when absent).

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/detector/dnn_detector.h>

#include "shared_data.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;
using scaled::core::BoundingBox;
using scaled::core::ErrorCode;
using scaled::drivers::detector::DetectionResult;
using scaled::drivers::detector::DetectorConfig;
using scaled::drivers::detector::DnnDetector;
using scaled::drivers::detector::ModelFamily;
using scaled::drivers::detector::ObjectDetection;
using scaled::test::TempDir;

// A file with `content` in the test's temporary directory.
fs::path writeFile(const TempDir& dir, const std::string& name, const std::string& content) {
    fs::path p = dir.path() / name;
    std::ofstream(p, std::ios::binary) << content;
    return p;
}

// The first `bytes` bytes of `src` as a new file.
fs::path truncatedCopy(const TempDir& dir, const fs::path& src, const std::string& name,
                       std::size_t bytes) {
    std::ifstream in(src, std::ios::binary);
    std::string data(bytes, '\0');
    in.read(data.data(), static_cast<std::streamsize>(bytes));
    data.resize(static_cast<std::size_t>(in.gcount()));
    return writeFile(dir, name, data);
}

std::string readAll(const fs::path& p) {
    std::string data(static_cast<std::size_t>(fs::file_size(p)), '\0');
    std::ifstream in(p, std::ios::binary);
    in.read(data.data(), static_cast<std::streamsize>(data.size()));
    return data;
}

double iou(const BoundingBox& a, const BoundingBox& b) {
    const double w = std::min(a.x_max_px, b.x_max_px) - std::max(a.x_min_px, b.x_min_px);
    const double h = std::min(a.y_max_px, b.y_max_px) - std::max(a.y_min_px, b.y_min_px);
    if (w <= 0 || h <= 0) {
        return 0;
    }
    const double area_a = (a.x_max_px - a.x_min_px) * (a.y_max_px - a.y_min_px);
    const double area_b = (b.x_max_px - b.x_min_px) * (b.y_max_px - b.y_min_px);
    return w * h / (area_a + area_b - w * h);
}

std::vector<ObjectDetection> ofClass(const DetectionResult& r, std::string_view name) {
    std::vector<ObjectDetection> out;
    for (const ObjectDetection& d : r.detections) {
        if (d.class_name == name) {
            out.push_back(d);
        }
    }
    return out;
}

// Every box inside the image, scores above the threshold and sorted.
void expectWellFormed(const DetectionResult& r, float threshold) {
    float last = 2;
    for (const ObjectDetection& d : r.detections) {
        EXPECT_GE(d.box.x_min_px, 0);
        EXPECT_GE(d.box.y_min_px, 0);
        EXPECT_LE(d.box.x_max_px, r.width_px - 1);
        EXPECT_LE(d.box.y_max_px, r.height_px - 1);
        EXPECT_LT(d.box.x_min_px, d.box.x_max_px);
        EXPECT_LT(d.box.y_min_px, d.box.y_max_px);
        EXPECT_GE(d.score, threshold);
        EXPECT_LE(d.score, 1.0F);
        EXPECT_LE(d.score, last);
        last = d.score;
        EXPECT_FALSE(d.class_name.empty());
    }
}

DetectorConfig yoloxConfig(const fs::path& model, int size = 416) {
    DetectorConfig c;
    c.family = ModelFamily::kYolox;
    c.model_path = model;
    c.input_size_px = size;
    return c;
}

DetectorConfig darknetConfig(const fs::path& cfg, int size = 320) {
    DetectorConfig c;
    c.family = ModelFamily::kDarknet;
    c.model_path = cfg;
    c.input_size_px = size;
    return c;
}

cv::Mat readImage(const fs::path& p, int flags = cv::IMREAD_COLOR) {
    cv::Mat m = cv::imread(p.string(), flags);
    EXPECT_FALSE(m.empty()) << p;
    return m;
}

// ---------------------------------------------------------------- config

TEST(DetectorConfig, EveryRangeErrorNamesItsField) {
    struct Case {
        DetectorConfig config;
        std::string field;
    };
    std::vector<Case> cases;
    const DetectorConfig base = yoloxConfig("model.onnx");
    for (const int s : {0, 48, 100, 1312}) {
        DetectorConfig c = base;
        c.input_size_px = s;
        cases.push_back({c, "input_size_px = " + std::to_string(s)});
    }
    for (const float t : {0.0F, -0.1F, 1.5F}) {
        DetectorConfig c = base;
        c.score_threshold = t;
        cases.push_back({c, "score_threshold"});
        c = base;
        c.nms_iou_threshold = t;
        cases.push_back({c, "nms_iou_threshold"});
    }
    DetectorConfig c = base;
    c.threads = -1;
    cases.push_back({c, "threads = -1"});
    c = base;
    c.max_detections = 0;
    cases.push_back({c, "max_detections = 0"});
    c = base;
    c.classes = {"chair", ""};
    cases.push_back({c, "classes"});
    c = base;
    c.model_path.clear();
    cases.push_back({c, "model_path"});
    for (const Case& k : cases) {
        auto r = scaled::drivers::detector::validate(k.config);
        ASSERT_FALSE(r.ok()) << k.field;
        EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
        EXPECT_NE(r.error().message.find(k.field), std::string::npos) << r.error().message;
    }
    EXPECT_TRUE(scaled::drivers::detector::validate(base).ok());
}

TEST(DetectorConfig, FamilyFromTextAndPath) {
    EXPECT_EQ(*scaled::drivers::detector::parseModelFamily("yolox"), ModelFamily::kYolox);
    EXPECT_EQ(*scaled::drivers::detector::parseModelFamily("darknet"), ModelFamily::kDarknet);
    auto bad = scaled::drivers::detector::parseModelFamily("yolov8");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("yolov8"), std::string::npos);
    EXPECT_EQ(scaled::drivers::detector::familyFromPath("a/yolo-fastest.CFG"),
              ModelFamily::kDarknet);
    EXPECT_EQ(scaled::drivers::detector::familyFromPath("a/yolox_nano.onnx"), ModelFamily::kYolox);
}

TEST(ClassNames, ReadsLinesAndNamesFileAndLineOfProblems) {
    TempDir tmp("detector");
    auto ok = scaled::drivers::detector::readClassNames(
        writeFile(tmp, "ok.names", "person\r\ndining table\n\n"));
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(*ok, (std::vector<std::string>{"person", "dining table"}));

    auto gap = scaled::drivers::detector::readClassNames(writeFile(tmp, "gap.names", "a\n\nb\n"));
    ASSERT_FALSE(gap.ok());
    EXPECT_NE(gap.error().message.find("gap.names:2:"), std::string::npos) << gap.error().message;

    auto empty = scaled::drivers::detector::readClassNames(writeFile(tmp, "empty.names", ""));
    ASSERT_FALSE(empty.ok());
    EXPECT_NE(empty.error().message.find("empty.names"), std::string::npos);

    auto blank = scaled::drivers::detector::readClassNames(writeFile(tmp, "blank.names", "\n\n"));
    ASSERT_FALSE(blank.ok());
    EXPECT_NE(blank.error().message.find("no class names"), std::string::npos);

    auto ctrl =
        scaled::drivers::detector::readClassNames(writeFile(tmp, "ctrl.names", "a\nb\x01\n"));
    ASSERT_FALSE(ctrl.ok());
    EXPECT_NE(ctrl.error().message.find("ctrl.names:2:"), std::string::npos);

    auto missing = scaled::drivers::detector::readClassNames(tmp.path() / "nope.names");
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
    EXPECT_NE(missing.error().message.find("nope.names"), std::string::npos);
}

TEST(DnnDetectorFiles, MissingModelOrWeightsIsNotFoundNamingTheFile) {
    TempDir tmp("detector");
    (void)writeFile(tmp, "coco.names", "a\nb\n");
    auto r = DnnDetector::create(yoloxConfig(tmp.path() / "absent.onnx"));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_NE(r.error().message.find("absent.onnx"), std::string::npos) << r.error().message;

    const fs::path cfg = writeFile(tmp, "net.cfg", "[net]\nwidth=320\nheight=320\n");
    auto d = DnnDetector::create(darknetConfig(cfg));
    ASSERT_FALSE(d.ok());
    EXPECT_EQ(d.error().code, ErrorCode::kNotFound);
    EXPECT_NE(d.error().message.find("net.weights"), std::string::npos) << d.error().message;

    auto e = DnnDetector::create(yoloxConfig(writeFile(tmp, "empty.onnx", "")));
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.error().message.find("empty.onnx"), std::string::npos);
    EXPECT_NE(e.error().message.find("empty"), std::string::npos);
}

TEST(DnnDetectorFiles, NotAnOnnxFileIsAParseErrorNamingTheFile) {
    TempDir tmp("detector");
    (void)writeFile(tmp, "coco.names", "a\nb\n");
    auto r = DnnDetector::create(yoloxConfig(writeFile(tmp, "text.onnx", "this is not a model\n")));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kParse);
    EXPECT_NE(r.error().message.find("text.onnx"), std::string::npos) << r.error().message;
}

TEST(DnnDetectorFiles, TruncatedOrWrongFormatRealModelsNameTheFile) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_MODEL(cfg, "yolo-fastest-1.1-xl.cfg");
    TempDir tmp("detector");
    fs::copy_file(onnx.parent_path() / "coco.names", tmp.path() / "coco.names");

    const fs::path cut = truncatedCopy(tmp, onnx, "cut.onnx", 1000000);
    auto a = DnnDetector::create(yoloxConfig(cut));
    ASSERT_FALSE(a.ok());
    EXPECT_EQ(a.error().code, ErrorCode::kParse);
    EXPECT_NE(a.error().message.find("cut.onnx"), std::string::npos) << a.error().message;

    // Darknet weights handed over as an ONNX model.
    const fs::path weights_as_onnx =
        writeFile(tmp, "weights.onnx", readAll(fs::path(cfg).replace_extension(".weights")));
    auto b = DnnDetector::create(yoloxConfig(weights_as_onnx));
    ASSERT_FALSE(b.ok());
    EXPECT_NE(b.error().message.find("weights.onnx"), std::string::npos) << b.error().message;

    // Truncated Darknet weights: OpenCV would load them silently (with zeros).
    fs::copy_file(cfg, tmp.path() / "net.cfg");
    (void)truncatedCopy(tmp, fs::path(cfg).replace_extension(".weights"), "net.weights", 2000000);
    auto c = DnnDetector::create(darknetConfig(tmp.path() / "net.cfg"));
    ASSERT_FALSE(c.ok());
    EXPECT_EQ(c.error().code, ErrorCode::kParse);
    EXPECT_NE(c.error().message.find("net.weights"), std::string::npos) << c.error().message;
    EXPECT_NE(c.error().message.find("truncated"), std::string::npos) << c.error().message;

    // An ONNX model given as a Darknet cfg.
    DetectorConfig onnx_as_cfg = darknetConfig(onnx);
    onnx_as_cfg.weights_path = onnx;
    auto d = DnnDetector::create(onnx_as_cfg);
    ASSERT_FALSE(d.ok());
    EXPECT_NE(d.error().message.find("yolox_nano.onnx"), std::string::npos) << d.error().message;
}

TEST(DnnDetectorFiles, ClassCountMismatchNamesModelAndNamesFile) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_MODEL(cfg, "yolo-fastest-1.1-xl.cfg");
    TempDir tmp("detector");
    auto names = scaled::drivers::detector::readClassNames(onnx.parent_path() / "coco.names");
    ASSERT_TRUE(names.ok());
    ASSERT_EQ(names->size(), 80U);
    std::string text;
    for (std::size_t i = 0; i + 1 < names->size(); ++i) {
        text += (*names)[i] + "\n";
    }
    const fs::path n79 = writeFile(tmp, "n79.names", text);
    for (DetectorConfig c : {yoloxConfig(onnx, 320), darknetConfig(cfg)}) {
        c.names_path = n79;
        auto r = DnnDetector::create(c);
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().code, ErrorCode::kParse);
        EXPECT_NE(r.error().message.find("n79.names"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find("80"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find("79"), std::string::npos) << r.error().message;
    }
}

TEST(DnnDetectorFiles, UnknownAllowListClassIsAnError) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    DetectorConfig c = yoloxConfig(onnx, 320);
    c.classes = {"chair", "sofa"};  // COCO 2017 spells it "couch"
    auto r = DnnDetector::create(c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("sofa"), std::string::npos) << r.error().message;
}

// ---------------------------------------------------------------- real frames

TEST(DnnDetectorReal, RedkitchenFrame0HasAChairAndADiningTable) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto det = DnnDetector::create(yoloxConfig(onnx));
    ASSERT_TRUE(det.ok()) << det.error().message;
    EXPECT_EQ((*det)->classNames().size(), 80U);
    EXPECT_EQ((*det)->info().class_count, 80);
    const cv::Mat img = readImage(dir / "rgb" / "000000.jpg");
    DetectionResult r;
    auto ok = (*det)->detect(img, 7, 123456789, r);
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(r.frame_id, 7);
    EXPECT_EQ(r.t_ns, 123456789);
    EXPECT_EQ(r.width_px, 640);
    EXPECT_EQ(r.height_px, 480);
    expectWellFormed(r, 0.3F);
    EXPECT_GE(ofClass(r, "chair").size(), 1U);
    ASSERT_EQ(ofClass(r, "dining table").size(), 1U);
    // The table fills the lower right of the frame.
    const BoundingBox table = ofClass(r, "dining table")[0].box;
    EXPECT_GT(table.x_max_px - table.x_min_px, 300);
    EXPECT_GT(table.y_max_px, 400);
    EXPECT_GT(r.timing.forward_ms, 0);

    // Same image, same answer.
    DetectionResult again;
    ASSERT_TRUE((*det)->detect(img, 8, 0, again).ok());
    ASSERT_EQ(again.detections.size(), r.detections.size());
    for (std::size_t i = 0; i < r.detections.size(); ++i) {
        EXPECT_EQ(again.detections[i].class_id, r.detections[i].class_id);
        EXPECT_FLOAT_EQ(again.detections[i].score, r.detections[i].score);
    }
}

TEST(DnnDetectorReal, AllowListAndSmallerInputSize) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    DetectorConfig c = yoloxConfig(onnx, 320);
    c.classes = {"chair"};
    auto det = DnnDetector::create(c);
    ASSERT_TRUE(det.ok()) << det.error().message;
    DetectionResult r;
    ASSERT_TRUE((*det)->detect(readImage(dir / "rgb" / "000000.jpg"), 0, 0, r).ok());
    ASSERT_FALSE(r.detections.empty());
    for (const ObjectDetection& d : r.detections) {
        EXPECT_EQ(d.class_name, "chair");
    }
    expectWellFormed(r, 0.3F);
}

TEST(DnnDetectorReal, TumOfficeFrameHasBottles) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "tum-fr3-office");
    std::vector<fs::path> images;
    for (const auto& e : fs::directory_iterator(dir / "rgb")) {
        images.push_back(e.path());
    }
    ASSERT_FALSE(images.empty());
    std::sort(images.begin(), images.end());
    auto det = DnnDetector::create(yoloxConfig(onnx));
    ASSERT_TRUE(det.ok()) << det.error().message;
    DetectionResult r;
    ASSERT_TRUE((*det)->detect(readImage(images.front()), 0, 0, r).ok());
    expectWellFormed(r, 0.3F);
    EXPECT_GE(ofClass(r, "bottle").size(), 3U);
}

TEST(DnnDetectorReal, KittiGrayFrameHasCars) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "kitti00");
    const cv::Mat gray = readImage(dir / "image_0" / "000000.png", cv::IMREAD_UNCHANGED);
    ASSERT_EQ(gray.channels(), 1);  // expanded to 3 channels by the detector
    auto det = DnnDetector::create(yoloxConfig(onnx));
    ASSERT_TRUE(det.ok()) << det.error().message;
    DetectionResult r;
    ASSERT_TRUE((*det)->detect(gray, 0, 0, r).ok());
    EXPECT_EQ(r.width_px, 1241);
    EXPECT_EQ(r.height_px, 376);
    expectWellFormed(r, 0.3F);
    const auto cars = ofClass(r, "car");
    ASSERT_GE(cars.size(), 1U);
    EXPECT_GT(cars[0].score, 0.6F);
}

// Yolo-Fastest is the weaker model: on redkitchen frame 0 it scores the chairs
// below the 0.2 floor of OpenCV's Darknet importer (class scores under it are
// zeroed), so the comparison is on frame 80, where both models see the chair
// at the table's far side.
TEST(DnnDetectorReal, DarknetFindsTheSameChairAsYolox) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_MODEL(cfg, "yolo-fastest-1.1-xl.cfg");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    const cv::Mat img = readImage(dir / "rgb" / "000080.jpg");
    auto yolox = DnnDetector::create(yoloxConfig(onnx));
    auto darknet = DnnDetector::create(darknetConfig(cfg));
    ASSERT_TRUE(yolox.ok()) << yolox.error().message;
    ASSERT_TRUE(darknet.ok()) << darknet.error().message;
    EXPECT_EQ((*darknet)->info().weights_path.filename(), "yolo-fastest-1.1-xl.weights");
    DetectionResult ry;
    DetectionResult rd;
    ASSERT_TRUE((*yolox)->detect(img, 80, 0, ry).ok());
    ASSERT_TRUE((*darknet)->detect(img, 80, 0, rd).ok());
    expectWellFormed(rd, 0.3F);
    const auto chairs_y = ofClass(ry, "chair");
    const auto chairs_d = ofClass(rd, "chair");
    ASSERT_FALSE(chairs_y.empty());
    ASSERT_FALSE(chairs_d.empty());
    double best = 0;
    for (const auto& a : chairs_d) {
        for (const auto& b : chairs_y) {
            best = std::max(best, iou(a.box, b.box));
        }
    }
    EXPECT_GT(best, 0.7) << "no Darknet chair overlaps a YOLOX chair";
}

TEST(DnnDetectorReal, GrayBgrAndBgraInputsAndBadImages) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto det = DnnDetector::create(yoloxConfig(onnx, 320));
    ASSERT_TRUE(det.ok()) << det.error().message;
    const cv::Mat bgr = readImage(dir / "rgb" / "000000.jpg");
    cv::Mat bgra;
    cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
    DetectionResult a;
    DetectionResult b;
    ASSERT_TRUE((*det)->detect(bgr, 0, 0, a).ok());
    ASSERT_TRUE((*det)->detect(bgra, 0, 0, b).ok());
    ASSERT_EQ(a.detections.size(), b.detections.size());

    DetectionResult r;
    auto empty = (*det)->detect(cv::Mat(), 3, 0, r);
    ASSERT_FALSE(empty.ok());
    EXPECT_EQ(empty.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(empty.error().message.find("frame 3"), std::string::npos);
    const cv::Mat depth16(48, 64, CV_16UC1, cv::Scalar(1000));
    EXPECT_FALSE((*det)->detect(depth16, 0, 0, r).ok());
    const cv::Mat two(48, 64, CV_8UC2, cv::Scalar(0, 0));
    EXPECT_FALSE((*det)->detect(two, 0, 0, r).ok());
    EXPECT_TRUE(r.detections.empty());
}

TEST(DnnDetectorReal, ThreadCountDoesNotChangeTheDetections) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    const cv::Mat img = readImage(dir / "rgb" / "000000.jpg");
    std::vector<DetectionResult> results;
    for (const int threads : {1, 2}) {
        DetectorConfig c = yoloxConfig(onnx, 320);
        c.threads = threads;
        auto det = DnnDetector::create(c);
        ASSERT_TRUE(det.ok()) << det.error().message;
        EXPECT_EQ(cv::getNumThreads(), threads);
        results.emplace_back();
        ASSERT_TRUE((*det)->detect(img, 0, 0, results.back()).ok());
    }
    ASSERT_EQ(results[0].detections.size(), results[1].detections.size());
    for (std::size_t i = 0; i < results[0].detections.size(); ++i) {
        EXPECT_EQ(results[0].detections[i].class_id, results[1].detections[i].class_id);
        EXPECT_NEAR(results[0].detections[i].score, results[1].detections[i].score, 1e-4F);
        EXPECT_NEAR(results[0].detections[i].box.x_min_px, results[1].detections[i].box.x_min_px,
                    0.05);
    }
}

TEST(DnnDetectorReal, EstimatorDetectionsViewTheDetectorsNames) {
    SCALED_REQUIRE_MODEL(onnx, "yolox_nano.onnx");
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto det = DnnDetector::create(yoloxConfig(onnx, 320));
    ASSERT_TRUE(det.ok()) << det.error().message;
    DetectionResult r;
    ASSERT_TRUE((*det)->detect(readImage(dir / "rgb" / "000000.jpg"), 0, 0, r).ok());
    ASSERT_GE(r.detections.size(), 2U);
    std::vector<scaled::core::Detection> out(1);
    EXPECT_EQ(scaled::drivers::detector::toEstimatorDetections(r, out), 1U);
    EXPECT_EQ(out[0].class_name, r.detections[0].class_name);
    EXPECT_EQ(out[0].box.x_min_px, r.detections[0].box.x_min_px);
    EXPECT_FLOAT_EQ(static_cast<float>(out[0].score), r.detections[0].score);
}

}  // namespace
