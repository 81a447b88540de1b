#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_kitti.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/trajectory_io.h>
#include <scaled/drivers/source/frame_selection.h>
#include <scaled/drivers/source/frame_source.h>

#include "dataset_test_util.h"
#include "shared_data.h"

namespace scaled::drivers::dataset {
namespace {

namespace fs = std::filesystem;
using core::CameraPose;
using core::ErrorCode;
using core::Scalar;

// Tolerance on numbers read back from text (float-clean when Scalar is float).
constexpr bool kFloat = std::is_same_v<Scalar, float>;
constexpr double kReadTol = kFloat ? 1e-5 : 1e-9;

using test::readFile;
using test::TempDir;
using test::tinyImage;
using test::writeFile;

// TUM-like dataset: rgb/0.png .. rgb/{n-1}.png, rgb.txt, groundtruth.txt, camera.txt.
constexpr std::string_view kRgbTxt =
    "# timestamp filename\n"
    "0.000000 rgb/0.png\n"
    "0.033333 rgb/1.png\n"
    "0.066667 rgb/2.png\n";
constexpr std::string_view kGtTxt =
    "# timestamp tx ty tz qx qy qz qw\n"
    "0.000000 0.1 0.2 0.3 0 0 0 1\n"
    "0.033333 0.2 0.2 0.3 0 0 0.7071068 0.7071068\n"
    "0.066667 0.3 0.2 0.3 0.5 0.5 0.5 0.5\n";
constexpr std::string_view kCameraTxt =
    "# width height fx fy cx cy\n"
    "8 6 10 11 4 3\n";
constexpr std::string_view kAccelTxt =
    "# timestamp ax ay az\n"
    "0.001000 0.1 -9.7 0.2\n"
    "0.040000 0.2 -9.8 0.3\n"
    "0.500000 0.0 -9.81 0.0\n";

void makeTumDataset(const fs::path& dir, int images = 3) {
    fs::create_directories(dir / "rgb");
    for (int i = 0; i < images; ++i) {
        ASSERT_TRUE(
            cv::imwrite((dir / "rgb" / (std::to_string(i) + ".png")).string(), tinyImage(i)));
    }
    writeFile(dir / "rgb.txt", kRgbTxt);
    writeFile(dir / "groundtruth.txt", kGtTxt);
    writeFile(dir / "camera.txt", kCameraTxt);
}

void makeKittiDataset(const fs::path& dir, int images = 3) {
    fs::create_directories(dir / "image_0");
    for (int i = 0; i < images; ++i) {
        cv::Mat gray;
        cv::cvtColor(tinyImage(i), gray, cv::COLOR_BGR2GRAY);
        char name[32];
        std::snprintf(name, sizeof name, "%06d.png", i);
        ASSERT_TRUE(cv::imwrite((dir / "image_0" / name).string(), gray));
    }
    writeFile(dir / "times.txt", "0.000000e+00\n1.000000e-01\n2.000000e-01\n");
    writeFile(dir / "poses.txt",
              "1 0 0 0 0 1 0 0 0 0 1 0\n"
              "1 0 0 0.5 0 1 0 0 0 0 1 1\n"
              "1 0 0 1.0 0 1 0 0 0 0 1 2\n");
    writeFile(dir / "calib.txt", "P0: 10 0 4 0 0 11 3 0 0 0 1 0\nP1: 10 0 4 -5 0 11 3 0 0 0 1 0\n");
}

// Reads every frame; returns the number read, stops at the first error.
struct ReadAll {
    std::size_t frames = 0;
    std::optional<core::Error> error;
};
ReadAll readAll(source::FrameSource& src) {
    ReadAll out;
    source::Frame f;
    while (true) {
        auto r = src.next(f);
        if (!r) {
            out.error = r.error();
            return out;
        }
        if (!*r) {
            return out;
        }
        ++out.frames;
    }
}

Eigen::Matrix3d rotationFromTum(double qx, double qy, double qz, double qw) {
    return Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
}

double rotationError(const core::Mat3& R, const Eigen::Matrix3d& expected) {
    return (R.cast<double>() - expected).cwiseAbs().maxCoeff();
}

// ---------------------------------------------------------------- real data

TEST(DatasetReal, RedkitchenOpensWithIntrinsicsGravityAndGroundTruth) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.name, "redkitchen");
    EXPECT_EQ(info.frame_count, 600U);
    EXPECT_EQ(info.listed_count, 600U);
    ASSERT_TRUE(info.has_intrinsics);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.fx), 585.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.fy), 585.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.cx), 320.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.cy), 240.0);
    EXPECT_EQ(info.intrinsics.width_px, 640);
    EXPECT_EQ(info.intrinsics.height_px, 480);
    ASSERT_TRUE(info.gravity_down_W.has_value());
    EXPECT_NEAR(static_cast<double>(info.gravity_down_W->norm()), 1.0, 1e-6);
    EXPECT_NEAR(static_cast<double>(info.gravity_down_W->y()), 0.904425559, 1e-4);
    EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.001);  // depth.txt says millimetres

    source::Frame f;
    auto r = (*src)->next(f);
    ASSERT_TRUE(r) << r.error().message;
    ASSERT_TRUE(*r);
    EXPECT_EQ(f.id, 0);
    EXPECT_EQ(f.t_ns, 0);
    EXPECT_EQ(f.gray.type(), CV_8UC1);
    EXPECT_EQ(f.color.type(), CV_8UC3);
    EXPECT_EQ(f.gray.cols, 640);
    EXPECT_EQ(f.gray.rows, 480);
    EXPECT_EQ(f.color.size(), f.gray.size());
    ASSERT_TRUE(f.depth_path.has_value());
    EXPECT_EQ(f.depth_path->filename(), "000000.png");
    // First line of groundtruth.txt:
    // 0.000000 -0.3404563 0.0164698 0.2965692 -0.0002124 -0.1608336 -0.1394795 0.9770762
    ASSERT_TRUE(f.T_CtoW_gt.has_value());
    EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), -0.3404563, kReadTol);
    EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.y()), 0.0164698, kReadTol);
    EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.z()), 0.2965692, kReadTol);
    EXPECT_LT(rotationError(f.T_CtoW_gt->R_CtoW,
                            rotationFromTum(-0.0002124, -0.1608336, -0.1394795, 0.9770762)),
              1e-6);
    // gravity.txt rotated into the camera: a handheld camera looks roughly
    // level, so down is mostly +y in the camera frame.
    ASSERT_TRUE(f.gravity_down_C.has_value());
    const core::Vec3 expected_down = f.T_CtoW_gt->R_CtoW.transpose() * *info.gravity_down_W;
    EXPECT_LT(static_cast<double>((*f.gravity_down_C - expected_down).norm()), 1e-6);
    EXPECT_GT(static_cast<double>(f.gravity_down_C->y()), 0.7);
    EXPECT_FALSE(f.accel_C.has_value());  // no accelerometer.txt

    r = (*src)->next(f);
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.id, 1);
    EXPECT_EQ(f.t_ns, 33333000);  // "0.033333" exactly

    // --frames A:B: seek, last frame, end.
    auto s = (*src)->seek(599);
    ASSERT_TRUE(s && *s);
    r = (*src)->next(f);
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.id, 599);
    EXPECT_TRUE(f.T_CtoW_gt.has_value());
    r = (*src)->next(f);
    ASSERT_TRUE(r);
    EXPECT_FALSE(*r);
    s = (*src)->seek(600);
    ASSERT_TRUE(s);
    EXPECT_FALSE(*s);
    s = (*src)->seek(601);
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().code, ErrorCode::kInvalidArgument);
}

TEST(DatasetReal, Kitti00HasCalibIntrinsicsTenHertzAndPoses) {
    SCALED_REQUIRE_DATASET(dir, "kitti00");
    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.frame_count, 160U);
    ASSERT_TRUE(info.has_intrinsics);
    // calib.txt P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0
    EXPECT_NEAR(static_cast<double>(info.intrinsics.fx), 718.856, 1e-3);
    EXPECT_NEAR(static_cast<double>(info.intrinsics.fy), 718.856, 1e-3);
    EXPECT_NEAR(static_cast<double>(info.intrinsics.cx), 607.1928, 1e-3);
    EXPECT_NEAR(static_cast<double>(info.intrinsics.cy), 185.2157, 1e-3);
    EXPECT_EQ(info.intrinsics.width_px, 1241);
    EXPECT_EQ(info.intrinsics.height_px, 376);
    EXPECT_FALSE(info.gravity_down_W.has_value());  // only when asked
    EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.0);

    source::Frame f;
    int64_t prev_t = -1;
    std::size_t n = 0;
    while (true) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        if (!*r) {
            break;
        }
        EXPECT_EQ(f.id, static_cast<int64_t>(n));
        EXPECT_EQ(f.gray.type(), CV_8UC1);
        EXPECT_EQ(f.color.type(), CV_8UC3);
        EXPECT_EQ(f.gray.cols, 1241);
        EXPECT_EQ(f.gray.rows, 376);
        ASSERT_TRUE(f.T_CtoW_gt.has_value()) << "frame " << n;
        if (n == 0) {
            EXPECT_EQ(f.t_ns, 0);
            // The expanded gray: all three channels equal the gray image.
            std::vector<cv::Mat> ch;
            cv::split(f.color, ch);
            EXPECT_EQ(cv::norm(ch[0], f.gray, cv::NORM_INF), 0.0);
            EXPECT_EQ(cv::norm(ch[2], f.gray, cv::NORM_INF), 0.0);
        } else {
            const double dt_s = static_cast<double>(f.t_ns - prev_t) * 1e-9;
            EXPECT_GT(dt_s, 0.09) << "frame " << n;
            EXPECT_LT(dt_s, 0.11) << "frame " << n;
        }
        if (n == 1) {
            EXPECT_EQ(f.t_ns, 103735900);  // "1.037359e-01" exactly
            // poses.txt line 2: ... -4.690294e-02 ... -2.839928e-02 ... 8.586941e-01
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), -4.690294e-02, kReadTol);
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.y()), -2.839928e-02, kReadTol);
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.z()), 8.586941e-01, kReadTol);
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->R_CtoW(0, 1)), 5.272628e-04, 1e-6);
        }
        prev_t = f.t_ns;
        ++n;
    }
    EXPECT_EQ(n, 160U);
    // The car drives forward along +z about 0.6-0.74 m per frame.
    EXPECT_GT(static_cast<double>(f.T_CtoW_gt->p_CinW.z()), 50.0);

    DatasetOptions opt;
    opt.gravity_from_groundtruth = true;
    auto with_g = openDataset(dir, opt);
    ASSERT_TRUE(with_g) << with_g.error().message;
    ASSERT_TRUE((*with_g)->info().gravity_down_W.has_value());
    EXPECT_NEAR(static_cast<double>((*with_g)->info().gravity_down_W->y()), 1.0, 1e-6);
}

// rgb.txt of the TUM sequence lists 2586 images; only the first 16 are in
// ../shared (a partial download). The default replays those 16 and says so.
TEST(DatasetReal, TumOfficePartialDownloadReplaysTheImagesThatExist) {
    SCALED_REQUIRE_DATASET(dir, "tum-fr3-office");
    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.frame_count, 16U);
    EXPECT_GT(info.listed_count, 16U);
    EXPECT_FALSE(info.has_intrinsics);  // no camera.txt: the caller supplies them
    EXPECT_FALSE(info.gravity_down_W.has_value());
    EXPECT_DOUBLE_EQ(info.depth_scale_m, 1.0 / 5000.0);
    const bool noted = std::any_of(info.notes.begin(), info.notes.end(), [](const std::string& n) {
        return n.find("only the first 16") != std::string::npos;
    });
    EXPECT_TRUE(noted);

    source::Frame f;
    for (std::size_t i = 0; i < 16; ++i) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        ASSERT_TRUE(*r);
        EXPECT_EQ(f.gray.cols, 640);
        EXPECT_EQ(f.gray.rows, 480);
        EXPECT_TRUE(f.depth_path.has_value()) << "frame " << i;
        // Ground truth starts at 1341847980.7900: frames 0 (67 ms before) and 1
        // (35 ms) have none; every later one has a pose within 5 ms.
        EXPECT_EQ(f.T_CtoW_gt.has_value(), i >= 2) << "frame " << i;
        if (i == 0) {
            EXPECT_EQ(f.t_ns, 1341847980722988000);
        }
        if (i == 2) {
            // 1341847980.786856 -> groundtruth 1341847980.7900 -0.6832 2.6909 1.7373 ...
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), -0.6832, kReadTol);
            EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.z()), 1.7373, kReadTol);
        }
    }
    auto end = (*src)->next(f);
    ASSERT_TRUE(end);
    EXPECT_FALSE(*end);

    // Intrinsics from the configuration; the image size from the first image.
    DatasetOptions opt;
    opt.intrinsics = core::CameraIntrinsics{
        Scalar(535.4), Scalar(539.2), Scalar(320.1), Scalar(247.6), 0, 0, 0, 0};
    auto with_k = openDataset(dir, opt);
    ASSERT_TRUE(with_k) << with_k.error().message;
    ASSERT_TRUE((*with_k)->info().has_intrinsics);
    EXPECT_EQ((*with_k)->info().intrinsics.width_px, 640);
    EXPECT_EQ((*with_k)->info().intrinsics.height_px, 480);
    EXPECT_NEAR(static_cast<double>((*with_k)->info().intrinsics.fy), 539.2, 1e-4);
}

TEST(DatasetReal, TumOfficeStrictModeReportsTheFirstMissingImageWithItsLine) {
    SCALED_REQUIRE_DATASET(dir, "tum-fr3-office");
    DatasetOptions opt;
    opt.drop_missing_tail = false;
    auto src = openDataset(dir, opt);
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, (*src)->info().listed_count);
    // The line of rgb.txt naming the 17th image.
    std::size_t line_no = 0;
    std::size_t data = 0;
    std::string name;
    {
        std::istringstream in(readFile(dir / "rgb.txt"));
        std::string line;
        while (std::getline(in, line)) {
            ++line_no;
            if (!line.empty() && line[0] != '#' && ++data == 17) {
                name = line.substr(line.find(' ') + 1);
                break;
            }
        }
    }
    ASSERT_EQ(data, 17U);
    const ReadAll all = readAll(**src);
    EXPECT_EQ(all.frames, 16U);
    ASSERT_TRUE(all.error.has_value());
    EXPECT_EQ(all.error->code, ErrorCode::kNotFound);
    EXPECT_NE(all.error->message.find("rgb.txt:" + std::to_string(line_no) + ":"),
              std::string::npos)
        << all.error->message;
    EXPECT_NE(all.error->message.find(name), std::string::npos) << all.error->message;
}

// ---------------------------------------------------------------- synthetic datasets

TEST(DatasetTum, ReadsASmallDataset) {
    TempDir tmp("tum");
    makeTumDataset(tmp.path());
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.frame_count, 3U);
    ASSERT_TRUE(info.has_intrinsics);
    EXPECT_EQ(info.intrinsics.width_px, 8);
    EXPECT_EQ(info.intrinsics.height_px, 6);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.fy), 11.0);
    EXPECT_FALSE(info.gravity_down_W.has_value());
    EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.0);

    source::Frame f;
    for (int i = 0; i < 3; ++i) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        ASSERT_TRUE(*r);
        EXPECT_EQ(f.id, i);
        EXPECT_EQ(cv::norm(f.color, tinyImage(i), cv::NORM_INF), 0.0);  // PNG is lossless
        cv::Mat gray;
        cv::cvtColor(tinyImage(i), gray, cv::COLOR_BGR2GRAY);
        EXPECT_EQ(cv::norm(f.gray, gray, cv::NORM_INF), 0.0);
        ASSERT_TRUE(f.T_CtoW_gt.has_value());
        EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), 0.1 * (i + 1), kReadTol);
    }
    EXPECT_EQ(f.t_ns, 66667000);
    // Third pose: q = (0.5, 0.5, 0.5, 0.5), a 120 degree turn about (1,1,1).
    EXPECT_LT(rotationError(f.T_CtoW_gt->R_CtoW, rotationFromTum(0.5, 0.5, 0.5, 0.5)), 1e-6);
}

TEST(FrameSelection, StrideReadsEveryNthFrameAndBlankedFramesAreBlack) {
    TempDir tmp("tum-select");
    makeTumDataset(tmp.path());
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    source::FrameSelection sel;
    sel.stride = 2;
    sel.blank.push_back({2, 3});
    source::Frame f;
    std::vector<std::int64_t> ids;
    for (std::size_t i = 0; i < (*src)->info().frame_count; i += sel.stride) {
        auto r = source::readSelected(**src, sel, i, f);
        ASSERT_TRUE(r) << r.error().message;
        ASSERT_TRUE(*r);
        ids.push_back(f.id);
        ASSERT_FALSE(f.gray.empty());
        const bool black = cv::countNonZero(f.gray) == 0;
        EXPECT_EQ(black, f.id == 2) << "frame " << f.id;
        EXPECT_TRUE(f.T_CtoW_gt.has_value()) << "a blanked frame keeps its time and ground truth";
    }
    EXPECT_EQ(ids, (std::vector<std::int64_t>{0, 2}));
    EXPECT_EQ(f.color.size(), tinyImage(0).size());
    EXPECT_EQ(cv::norm(f.color, cv::NORM_INF), 0.0);
    // Past the end: false, as next() says.
    auto end = source::readSelected(**src, sel, 3, f);
    ASSERT_TRUE(end);
    EXPECT_FALSE(*end);
}

TEST(FrameSelection, BlankRangesParseAndBadOnesAreNamed) {
    auto r = source::parseBlankRange("300:320");
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_EQ(r->first, 300U);
    EXPECT_EQ(r->end, 320U);
    source::FrameSelection sel;
    sel.blank.push_back(*r);
    EXPECT_FALSE(sel.blanked(299));
    EXPECT_TRUE(sel.blanked(300));
    EXPECT_TRUE(sel.blanked(319));
    EXPECT_FALSE(sel.blanked(320));
    EXPECT_FALSE(sel.blanked(-1));
    for (const char* bad : {"", ":", "5", "5:", ":5", "5:5", "6:5", "a:9", "1:2x", "-1:3"}) {
        const auto e = source::parseBlankRange(bad);
        ASSERT_FALSE(e) << bad;
        EXPECT_NE(e.error().message.find(std::string("'") + bad + "'"), std::string::npos)
            << e.error().message;
    }
}

TEST(DatasetTum, AssociatesGroundTruthAndDepthByNearestTimestamp) {
    TempDir tmp("assoc");
    makeTumDataset(tmp.path());
    // GT 10 ms after frame 0, none within 0.02 s of frame 1 (23 and 30 ms), exact at frame 2.
    writeFile(tmp.path() / "groundtruth.txt",
              "0.010000 1 0 0 0 0 0 1\n"
              "0.063333 2 0 0 0 0 0 1\n"
              "0.066667 3 0 0 0 0 0 1\n");
    fs::create_directories(tmp.path() / "depth");
    ASSERT_TRUE(cv::imwrite((tmp.path() / "depth" / "a.png").string(),
                            cv::Mat(6, 8, CV_16UC1, cv::Scalar(0))));
    writeFile(tmp.path() / "depth.txt",
              "# depth maps\n0.001 depth/a.png\n0.050 depth/missing.png\n");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_DOUBLE_EQ((*src)->info().depth_scale_m, 1.0 / 5000.0);
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.T_CtoW_gt.has_value());
    EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), 1.0, kReadTol);
    ASSERT_TRUE(f.depth_path.has_value());
    EXPECT_EQ(f.depth_path->filename(), "a.png");
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_EQ(f.id, 1);
    EXPECT_FALSE(f.T_CtoW_gt.has_value());   // nearest GT is 23 ms away
    EXPECT_FALSE(f.depth_path.has_value());  // nearest depth file does not exist
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.T_CtoW_gt.has_value());
    EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.x()), 3.0, kReadTol);

    DatasetOptions wide;
    wide.max_assoc_dt_s = 0.05;
    auto src2 = openDataset(tmp.path(), wide);
    ASSERT_TRUE(src2);
    ASSERT_TRUE((*src2)->seek(1).ok());
    ASSERT_TRUE((*src2)->next(f).ok());
    EXPECT_TRUE(f.T_CtoW_gt.has_value());

    wide.max_assoc_dt_s = -1;
    EXPECT_FALSE(openDataset(tmp.path(), wide).ok());
}

TEST(DatasetTum, GravityFileAndIntrinsicsOverride) {
    TempDir tmp("gravity");
    makeTumDataset(tmp.path());
    writeFile(tmp.path() / "gravity.txt", "# down\n0 0.6 0.8\n");
    DatasetOptions opt;
    opt.intrinsics = core::CameraIntrinsics{20, 20, 4, 3, 0, 0, 0, 0};
    auto src = openDataset(tmp.path(), opt);
    ASSERT_TRUE(src) << src.error().message;
    ASSERT_TRUE((*src)->info().gravity_down_W.has_value());
    EXPECT_NEAR(static_cast<double>((*src)->info().gravity_down_W->z()), 0.8, 1e-6);
    EXPECT_DOUBLE_EQ(static_cast<double>((*src)->info().intrinsics.fx), 20.0);
    EXPECT_EQ((*src)->info().intrinsics.width_px, 8);  // from the first image

    // TUM without gravity.txt: nothing is derived from the ground truth.
    fs::remove(tmp.path() / "gravity.txt");
    opt.gravity_from_groundtruth = true;
    auto src2 = openDataset(tmp.path(), opt);
    ASSERT_TRUE(src2);
    EXPECT_FALSE((*src2)->info().gravity_down_W.has_value());
}

TEST(DatasetTum, AccelerometerIsAssociatedByNearestTimestampAndKeptRaw) {
    TempDir tmp("accel");
    makeTumDataset(tmp.path());
    // Frame 0 (0 s): sample 1 ms away. Frame 1 (33.3 ms): 6.7 ms away. Frame 2
    // (66.7 ms): the nearest sample is 26.7 ms away, beyond max_assoc_dt_s.
    writeFile(tmp.path() / "accelerometer.txt", kAccelTxt);
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    const auto& notes = (*src)->info().notes;
    EXPECT_TRUE(std::any_of(notes.begin(), notes.end(), [](const std::string& n) {
        return n.find("accelerometer.txt: 1 of 3 frames have no sample") != std::string::npos;
    }));
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.accel_C.has_value());
    EXPECT_NEAR(static_cast<double>(f.accel_C->x()), 0.1, kReadTol);
    EXPECT_NEAR(static_cast<double>(f.accel_C->y()), -9.7, kReadTol);  // raw: sign unchanged
    EXPECT_NEAR(static_cast<double>(f.accel_C->z()), 0.2, kReadTol);
    // No gravity.txt: no gravity direction, whatever the accelerometer says.
    EXPECT_FALSE(f.gravity_down_C.has_value());
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.accel_C.has_value());
    EXPECT_NEAR(static_cast<double>(f.accel_C->y()), -9.8, kReadTol);
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_FALSE(f.accel_C.has_value());

    DatasetOptions wide;
    wide.max_assoc_dt_s = 0.03;
    auto src2 = openDataset(tmp.path(), wide);
    ASSERT_TRUE(src2) << src2.error().message;
    ASSERT_TRUE((*src2)->seek(2).ok());
    ASSERT_TRUE((*src2)->next(f).ok());
    ASSERT_TRUE(f.accel_C.has_value());
    EXPECT_NEAR(static_cast<double>(f.accel_C->z()), 0.3, kReadTol);
}

TEST(DatasetTum, GravityInTheCameraFrameComesFromGroundTruthEvenWithAnAccelerometer) {
    TempDir tmp("gravity_c");
    makeTumDataset(tmp.path());
    writeFile(tmp.path() / "gravity.txt", "0 0.6 0.8\n");
    writeFile(tmp.path() / "accelerometer.txt", kAccelTxt);
    // Frame 1 has no ground truth (nearest pose 30 ms away).
    writeFile(tmp.path() / "groundtruth.txt",
              "0.000000 0 0 0 0 0 0 1\n"
              "0.063333 0 0 0 0 0 0.7071068 0.7071068\n"
              "0.066667 0 0 0 0 0 0.7071068 0.7071068\n");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    // Frame 0: identity pose, down_C = down_W; the accelerometer is there too
    // but is not used for gravity.
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.accel_C.has_value());
    ASSERT_TRUE(f.gravity_down_C.has_value());
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->x()), 0.0, 1e-6);
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->y()), 0.6, 1e-6);
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->z()), 0.8, 1e-6);
    // Frame 1: accelerometer but no pose: no gravity direction.
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_TRUE(f.accel_C.has_value());
    EXPECT_FALSE(f.T_CtoW_gt.has_value());
    EXPECT_FALSE(f.gravity_down_C.has_value());
    // Frame 2: camera turned 90 degrees about z: R^T (0, 0.6, 0.8) = (0.6, 0, 0.8).
    ASSERT_TRUE((*src)->next(f).ok());
    ASSERT_TRUE(f.gravity_down_C.has_value());
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->x()), 0.6, 1e-6);
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->y()), 0.0, 1e-6);
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->z()), 0.8, 1e-6);
    EXPECT_NEAR(static_cast<double>(f.gravity_down_C->norm()), 1.0, 1e-6);
}

TEST(DatasetKitti, GravityFromGroundTruthGivesGravityInEveryCameraFrame) {
    TempDir tmp("kitti_g");
    makeKittiDataset(tmp.path());
    DatasetOptions opt;
    opt.gravity_from_groundtruth = true;
    auto src = openDataset(tmp.path(), opt);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE((*src)->next(f).ok());
        ASSERT_TRUE(f.gravity_down_C.has_value()) << i;
        EXPECT_NEAR(static_cast<double>(f.gravity_down_C->y()), 1.0, 1e-6) << i;
        EXPECT_FALSE(f.accel_C.has_value());
    }
    auto plain = openDataset(tmp.path());
    ASSERT_TRUE(plain);
    ASSERT_TRUE((*plain)->next(f).ok());
    EXPECT_FALSE(f.gravity_down_C.has_value());
}

TEST(DatasetTum, MissingImageInTheMiddleIsAnErrorOfNextWithIndexLine) {
    TempDir tmp("hole");
    makeTumDataset(tmp.path());
    fs::remove(tmp.path() / "rgb" / "1.png");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, 3U);  // the last image exists: nothing dropped
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    auto r = (*src)->next(f);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_NE(r.error().message.find("rgb.txt:3:"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("rgb/1.png"), std::string::npos) << r.error().message;
    // The cursor moved past the bad frame.
    r = (*src)->next(f);
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_TRUE(*r);
    EXPECT_EQ(f.id, 2);
}

TEST(DatasetTum, MissingTailIsDroppedWithANoteUnlessStrict) {
    TempDir tmp("tail");
    makeTumDataset(tmp.path(), 1);
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, 1U);
    EXPECT_EQ((*src)->info().listed_count, 3U);
    EXPECT_FALSE((*src)->info().notes.empty());
    EXPECT_EQ(readAll(**src).frames, 1U);

    DatasetOptions strict;
    strict.drop_missing_tail = false;
    auto src2 = openDataset(tmp.path(), strict);
    ASSERT_TRUE(src2);
    const ReadAll all = readAll(**src2);
    EXPECT_EQ(all.frames, 1U);
    ASSERT_TRUE(all.error.has_value());
    EXPECT_NE(all.error->message.find("rgb.txt:3:"), std::string::npos) << all.error->message;

    fs::remove(tmp.path() / "rgb" / "0.png");
    auto none = openDataset(tmp.path());
    ASSERT_FALSE(none);
    EXPECT_EQ(none.error().code, ErrorCode::kNotFound);
    EXPECT_NE(none.error().message.find("rgb.txt:2:"), std::string::npos) << none.error().message;
}

TEST(DatasetTum, CorruptImageAndWrongSizeNameTheFile) {
    TempDir tmp("corrupt");
    makeTumDataset(tmp.path());
    writeFile(tmp.path() / "rgb" / "1.png", "\x89PNG\r\n\x1a\n this is not a png");
    cv::Mat big(12, 16, CV_8UC1, cv::Scalar(7));
    ASSERT_TRUE(cv::imwrite((tmp.path() / "rgb" / "2.png").string(), big));
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    auto r = (*src)->next(f);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find((tmp.path() / "rgb" / "1.png").string()), std::string::npos)
        << r.error().message;
    r = (*src)->next(f);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(r.error().message.find("2.png: image is 16x12"), std::string::npos)
        << r.error().message;
}

TEST(DatasetOpen, DetectsFormatAndRejectsOtherDirectories) {
    TempDir tmp("detect");
    auto empty = openDataset(tmp.path());
    ASSERT_FALSE(empty);
    EXPECT_EQ(empty.error().code, ErrorCode::kNotFound);
    EXPECT_NE(empty.error().message.find(tmp.path().string()), std::string::npos);

    auto missing = openDataset(tmp.path() / "nope");
    ASSERT_FALSE(missing);
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);

    DatasetOptions tum;
    tum.format = DatasetFormat::kTum;
    auto forced = openDataset(tmp.path(), tum);
    ASSERT_FALSE(forced);
    EXPECT_NE(forced.error().message.find("rgb.txt"), std::string::npos);
}

TEST(DatasetKitti, ReadsASmallSequence) {
    TempDir tmp("kitti");
    makeKittiDataset(tmp.path());
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.frame_count, 3U);
    ASSERT_TRUE(info.has_intrinsics);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.fx), 10.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.cx), 4.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.fy), 11.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(info.intrinsics.cy), 3.0);
    EXPECT_EQ(info.intrinsics.width_px, 8);
    EXPECT_EQ(info.intrinsics.height_px, 6);
    source::Frame f;
    for (int i = 0; i < 3; ++i) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        ASSERT_TRUE(*r);
        EXPECT_EQ(f.t_ns, int64_t{100000000} * i);
        ASSERT_TRUE(f.T_CtoW_gt.has_value());
        EXPECT_NEAR(static_cast<double>(f.T_CtoW_gt->p_CinW.z()), i, kReadTol);
        EXPECT_EQ(f.color.channels(), 3);
    }
    // Without calib.txt: no intrinsics, the caller decides.
    fs::remove(tmp.path() / "calib.txt");
    auto src2 = openDataset(tmp.path());
    ASSERT_TRUE(src2);
    EXPECT_FALSE((*src2)->info().has_intrinsics);
}

// ---------------------------------------------------------------- malformed index files

struct BadCase {
    const char* file;
    const char* content;
    int line;
    const char* says;  // a fragment of the message
};

void expectOpenError(const fs::path& dir, const BadCase& c) {
    auto src = openDataset(dir);
    ASSERT_FALSE(src) << c.file << ": " << c.content;
    const std::string& msg = src.error().message;
    const std::string where = (dir / c.file).string() + ":" + std::to_string(c.line) + ":";
    EXPECT_NE(msg.find(where), std::string::npos) << "expected " << where << " in: " << msg;
    EXPECT_NE(msg.find(c.says), std::string::npos) << "expected '" << c.says << "' in: " << msg;
}

TEST(DatasetMalformed, TumLinesNameFileAndLine) {
    const BadCase cases[] = {
        {"rgb.txt", "# c\n0.0 rgb/0.png\n0.1 rgb/1.png extra\n", 3, "expected 2 fields"},
        {"rgb.txt", "0.0\n", 1, "expected 2 fields"},
        {"rgb.txt", "# c\nabc rgb/0.png\n", 2, "not a number"},
        {"rgb.txt", "0.0 rgb/0.png\n1e rgb/1.png\n", 2, "not a number"},
        {"rgb.txt", "nan rgb/0.png\n", 1, "not finite"},
        {"rgb.txt", "inf rgb/0.png\n", 1, "not finite"},
        {"rgb.txt", "1e30 rgb/0.png\n", 1, "out of range"},
        {"rgb.txt", "0.1 rgb/0.png\n\n0.1 rgb/1.png\n", 3, "does not increase"},
        {"rgb.txt", "0.2 rgb/0.png\n0.1 rgb/1.png\n", 2, "does not increase"},
        {"groundtruth.txt", "0 1 2 3 0 0 0\n", 1, "expected 8 fields"},
        {"groundtruth.txt", "#\n0 1 2 x 0 0 0 1\n", 2, "tz is not a number"},
        {"groundtruth.txt", "0 1 2 inf 0 0 0 1\n", 1, "tz is not finite"},
        {"groundtruth.txt", "0 1 2 3 0 0 0 1\n0.1 1 2 nan 0 0 0 1\n", 2, "not finite"},
        {"groundtruth.txt", "0 1 2 3 0 0 0 2\n", 1, "quaternion is not unit"},
        {"groundtruth.txt", "0 1 2 3 0 0 0 0\n", 1, "quaternion is not unit"},
        {"groundtruth.txt", "0.5 1 2 3 0 0 0 1\n0.5 1 2 3 0 0 0 1\n", 2, "does not increase"},
        {"camera.txt", "8 6 10 11 4\n", 1, "expected 6 or 8 fields"},
        {"camera.txt", "# w h\n8 6 10 eleven 4 3\n", 2, "fy is not a number"},
        {"camera.txt", "8 6 -10 11 4 3\n", 1, "focal lengths"},
        {"camera.txt", "0 6 10 11 4 3\n", 1, "width must be an integer"},
        {"camera.txt", "8.5 6 10 11 4 3\n", 1, "width must be an integer"},
        {"camera.txt", "8 6 10 11 4 3\n8 6 10 11 4 3\n", 2, "second data line"},
        {"gravity.txt", "0 0 2\n", 1, "not a unit vector"},
        {"gravity.txt", "# g\n0 1\n", 2, "expected 3 fields"},
        {"gravity.txt", "0 1 z\n", 1, "gz is not a number"},
        {"depth.txt", "0.0 depth/0.png\n-0.5 depth/1.png\n", 2, "does not increase"},
        {"accelerometer.txt", "# t ax ay az\n0.0 0 9.8\n", 2, "expected 4 fields"},
        {"accelerometer.txt", "0.0 0 9.8 0\n0.0 0 9.8 0\n", 2, "does not increase"},
        {"accelerometer.txt", "0.0 0 g 0\n", 1, "ay is not a number"},
        {"accelerometer.txt", "0.0 0 0 nan\n", 1, "az is not finite"},
        {"accelerometer.txt", "0.0 2e4 0 0\n", 1, "implausibly large"},
    };
    for (const BadCase& c : cases) {
        SCOPED_TRACE(std::string(c.file) + ": " + c.content);
        TempDir tmp("bad_tum");
        makeTumDataset(tmp.path());
        writeFile(tmp.path() / c.file, c.content);
        expectOpenError(tmp.path(), c);
    }
}

TEST(DatasetMalformed, KittiLinesNameFileAndLine) {
    const BadCase cases[] = {
        {"times.txt", "0.0\n0.1 0.2\n", 2, "expected 1 field"},
        {"times.txt", "0.0\nzero\n", 2, "not a number"},
        {"times.txt", "0.0\n0.1\n0.1\n", 3, "does not increase"},
        {"poses.txt", "1 0 0 0 0 1 0 0 0 0 1\n", 1, "expected 12 fields"},
        {"poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n", 2, "not orthonormal"},
        {"poses.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n", 1, "not orthonormal"},  // a reflection
        {"poses.txt", "1 0 0 0 0 1 0 0 0 0 1 nan\n", 1, "not finite"},
        {"calib.txt", "P0: 10 0 4 0 0 11 3 0 0 0 1\n", 1, "12 numbers"},
        {"calib.txt", "P1: 1\nP0: 10 0 4 0 0 11 3 0 0 0 1 x\n", 2, "not a number"},
        {"calib.txt", "P0: 10 0 4 0 0 11 3 0 0 0 1 0\nP0: 10 0 4 0 0 11 3 0 0 0 1 0\n", 2,
         "second P0: line"},
    };
    for (const BadCase& c : cases) {
        SCOPED_TRACE(std::string(c.file) + ": " + c.content);
        TempDir tmp("bad_kitti");
        makeKittiDataset(tmp.path());
        writeFile(tmp.path() / c.file, c.content);
        expectOpenError(tmp.path(), c);
    }
    TempDir tmp("bad_kitti_p0");
    makeKittiDataset(tmp.path());
    writeFile(tmp.path() / "calib.txt", "P1: 1 2 3\n");
    auto src = openDataset(tmp.path());
    ASSERT_FALSE(src);
    EXPECT_NE(src.error().message.find("calib.txt: no `P0:` line"), std::string::npos)
        << src.error().message;
}

TEST(DatasetMalformed, MessagesShowOffendingTextPrintably) {
    TempDir tmp("printable");
    makeTumDataset(tmp.path());
    writeFile(tmp.path() / "rgb.txt", std::string("0.0 rgb/0.png\n0.1\x01\xff rgb/1.png\n"));
    auto src = openDataset(tmp.path());
    ASSERT_FALSE(src);
    EXPECT_NE(src.error().message.find("rgb.txt:2:"), std::string::npos);
    EXPECT_NE(src.error().message.find("(0.1\\x01\\xff rgb/1.png)"), std::string::npos)
        << src.error().message;
}

// ---------------------------------------------------------------- fuzz

// Random mutations of a valid index: opening and reading must never crash, and
// every failure is an Error with a message. (CI runs this under ASan/UBSan.)
TEST(DatasetFuzz, MutatedIndexFilesNeverCrash) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("fuzz");
    const fs::path& dir = tmp.path();
    makeTumDataset(dir);
    // Odd files a mutated name may point at.
    writeFile(dir / "rgb" / "bad.png", "\x89PNG\r\n\x1a\nbroken");
    ASSERT_TRUE(
        cv::imwrite((dir / "rgb" / "deep.png").string(), cv::Mat(6, 8, CV_16UC1, cv::Scalar(0))));
    ASSERT_TRUE(
        cv::imwrite((dir / "rgb" / "big.png").string(), cv::Mat(12, 16, CV_8UC1, cv::Scalar(0))));
    fs::create_directories(dir / "rgb" / "dir.png");
    const std::array<std::string, 5> names = {"rgb.txt", "groundtruth.txt", "camera.txt",
                                              "gravity.txt", "accelerometer.txt"};
    const std::array<std::string, 5> base = {std::string(kRgbTxt), std::string(kGtTxt),
                                             std::string(kCameraTxt), "0 0.6 0.8\n",
                                             std::string(kAccelTxt)};
    test::TextMutator mutator(
        20240611,
        {"1e400", "-0", "9223372036.854775808", "nan", "-inf", "0.5", "#", "", "rgb/bad.png",
         "rgb/deep.png", "rgb/dir.png", "rgb/none.png", "/", "rgb/big.png", "1e4", "-10001"});
    const auto pick = [&](std::size_t n) { return mutator.pick(n); };

    constexpr int kIterations = 3000;
    fs::path run;
    int opened = 0;
    int frames_read = 0;
    int frame_errors = 0;
    int with_accel = 0;
    for (int it = 0; it < kIterations; ++it) {
        const std::array<std::string, 5> text = mutator.mutated(base);
        run = test::freshRunDir(dir, it, run);
        fs::create_directory_symlink(dir / "rgb", run / "rgb");
        for (std::size_t k = 0; k < names.size(); ++k) {
            writeFile(run / names[k], text[k]);
        }

        DatasetOptions opt;
        opt.drop_missing_tail = pick(2) == 0;
        auto src = openDataset(run, opt);
        if (!src) {
            ASSERT_FALSE(src.error().message.empty()) << "iteration " << it;
            continue;
        }
        ++opened;
        source::FrameSource& fsrc = **src;
        const source::SequenceInfo& info = fsrc.info();
        ASSERT_GE(info.frame_count, 1U);
        ASSERT_LE(info.frame_count, info.listed_count);
        if (info.has_intrinsics) {
            ASSERT_GT(info.intrinsics.fx, 0);
            ASSERT_GT(info.intrinsics.width_px, 0);
        }
        if (info.gravity_down_W) {
            ASSERT_NEAR(static_cast<double>(info.gravity_down_W->norm()), 1.0, 1e-5);
        }
        if (pick(4) == 0) {
            auto s = fsrc.seek(pick(info.frame_count + 2));
            if (!s) {
                ASSERT_FALSE(s.error().message.empty());
            }
        }
        source::Frame f;
        std::optional<int64_t> prev_t;
        for (std::size_t guard = 0; guard <= info.frame_count; ++guard) {
            auto r = fsrc.next(f);
            if (!r) {
                ASSERT_FALSE(r.error().message.empty()) << "iteration " << it;
                ++frame_errors;
                prev_t.reset();
                continue;
            }
            if (!*r) {
                break;
            }
            ++frames_read;
            ASSERT_EQ(f.gray.type(), CV_8UC1);
            ASSERT_EQ(f.color.type(), CV_8UC3);
            ASSERT_EQ(f.gray.size(), f.color.size());
            if (prev_t) {
                ASSERT_GT(f.t_ns, *prev_t) << "iteration " << it;
            }
            prev_t = f.t_ns;
            if (f.T_CtoW_gt) {
                const Eigen::Matrix3d R = f.T_CtoW_gt->R_CtoW.cast<double>();
                ASSERT_TRUE(R.allFinite());
                ASSERT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(),
                          1e-4);
                ASSERT_TRUE(f.T_CtoW_gt->p_CinW.allFinite());
            }
            if (f.gravity_down_C) {
                ASSERT_TRUE(f.T_CtoW_gt.has_value());
                ASSERT_NEAR(static_cast<double>(f.gravity_down_C->norm()), 1.0, 1e-5);
            }
            if (f.accel_C) {
                ++with_accel;
                ASSERT_TRUE(f.accel_C->allFinite());
                ASSERT_LE(static_cast<double>(f.accel_C->cwiseAbs().maxCoeff()), 1e4);
            }
        }
    }
    std::cout << "[ fuzz     ] " << kIterations << " mutated datasets: " << opened << " opened, "
              << frames_read << " frames read (" << with_accel << " with accelerometer), "
              << frame_errors << " frame errors\n";
    // The mutations must leave both outcomes common, else the test tests little.
    EXPECT_GT(opened, kIterations / 10);
    EXPECT_LT(opened, kIterations);
    EXPECT_GT(frames_read, kIterations / 10);
    EXPECT_GT(frame_errors, 0);
    EXPECT_GT(with_accel, 0);
}

// The same for an image folder: mutated times.txt and camera.txt.
TEST(DatasetFuzz, MutatedFolderTimesNeverCrash) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("fuzz_folder");
    const fs::path& dir = tmp.path();
    fs::create_directories(dir / "images");
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE(cv::imwrite((dir / "images" / ("f" + std::to_string(i) + ".png")).string(),
                                tinyImage(i)));
    }
    const std::array<std::string, 2> names = {"times.txt", "camera.txt"};
    const std::array<std::string, 2> base = {"0.0\n0.1\n0.2\n", std::string(kCameraTxt)};
    test::TextMutator mutator(20240612, {"1e400", "-0", "9223372036.854775808", "nan", "-inf",
                                         "0.5", "#", "", "0", "1e-9", "100000"});
    const auto pick = [&](std::size_t n) { return mutator.pick(n); };
    constexpr int kIterations = 1500;
    int opened = 0;
    int frames_read = 0;
    fs::path run;
    for (int it = 0; it < kIterations; ++it) {
        const std::array<std::string, 2> text = mutator.mutated(base);
        run = test::freshRunDir(dir, it, run);
        for (int i = 0; i < 3; ++i) {
            const std::string name = "f" + std::to_string(i) + ".png";
            fs::create_symlink(dir / "images" / name, run / name);
        }
        for (std::size_t k = 0; k < names.size(); ++k) {
            if (pick(8) != 0) {  // sometimes the file is absent
                writeFile(run / names[k], text[k]);
            }
        }
        DatasetOptions opt;
        if (pick(6) == 0) {
            opt.folder_fps = std::array<double, 4>{0.5, 1e9, 0, -3}[pick(4)];
        }
        auto src = openDataset(run, opt);
        if (!src) {
            ASSERT_FALSE(src.error().message.empty()) << "iteration " << it;
            continue;
        }
        ++opened;
        source::FrameSource& fsrc = **src;
        ASSERT_EQ(fsrc.info().frame_count, 3U);
        source::Frame f;
        std::optional<int64_t> prev_t;
        for (std::size_t guard = 0; guard <= 3; ++guard) {
            auto r = fsrc.next(f);
            if (!r) {
                ASSERT_FALSE(r.error().message.empty()) << "iteration " << it;
                continue;
            }
            if (!*r) {
                break;
            }
            ++frames_read;
            ASSERT_EQ(f.id, static_cast<int64_t>(guard));
            if (prev_t) {
                ASSERT_GT(f.t_ns, *prev_t) << "iteration " << it;
            }
            prev_t = f.t_ns;
        }
    }
    std::cout << "[ fuzz     ] " << kIterations << " mutated folders: " << opened << " opened, "
              << frames_read << " frames read\n";
    EXPECT_GT(opened, kIterations / 10);
    EXPECT_LT(opened, kIterations);
    EXPECT_GT(frames_read, kIterations / 10);
}

// ---------------------------------------------------------------- trajectories

TEST(TimestampText, ParsesDecimalTextExactly) {
    const std::pair<const char*, int64_t> good[] = {
        {"1341847980.722988", 1341847980722988000},
        {"1.037359e-01", 103735900},
        {"0.033333", 33333000},
        {"0.000000e+00", 0},
        {"-2.5", -2500000000},
        {"+7", 7000000000},
        {"5.", 5000000000},
        {".25", 250000000},
        {"1e-10", 0},
        {"5e-10", 1},  // rounded half away from zero
        {"-5e-10", -1},
        {"1.0000000004", 1000000000},
        {"1.0000000005", 1000000001},
        {"0.00000000000000000000000001e26", 1000000000},
        {"9223372036.854775807", std::numeric_limits<int64_t>::max()},
        {"-9223372036.854775808", std::numeric_limits<int64_t>::min()},
    };
    for (const auto& [text, ns] : good) {
        auto t = parseTimestampNs(text);
        ASSERT_TRUE(t) << text << ": " << t.error().message;
        EXPECT_EQ(*t, ns) << text;
    }
    for (const char* text : {"", "-", ".", "1..2", "1e", "1e+", "abc", "0x10", "1 2", "nan", "-inf",
                             "9223372036.854775808", "1e19", "1e1000000000000"}) {
        auto t = parseTimestampNs(text);
        ASSERT_FALSE(t) << text;
        EXPECT_NE(t.error().message.find('\''), std::string::npos) << t.error().message;
    }
    EXPECT_EQ(formatTimestampS(1341847980722988000), "1341847980.722988");
    EXPECT_EQ(formatTimestampS(0), "0.000000");
    EXPECT_EQ(formatTimestampS(1500), "0.000002");
    EXPECT_EQ(formatTimestampS(-1500), "-0.000002");
    EXPECT_EQ(formatTimestampS(-400), "0.000000");
    EXPECT_EQ(formatTimestampS(std::numeric_limits<int64_t>::min()), "-9223372036.854776");
    EXPECT_EQ(formatTimestampS(std::numeric_limits<int64_t>::max()), "9223372036.854776");
}

TEST(TrajectoryIo, RoundTripKeepsTimestampsAndPoses) {
    TempDir tmp("traj");
    std::mt19937 rng(7);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::uniform_real_distribution<double> pos(-100.0, 100.0);
    std::uniform_int_distribution<int64_t> jitter(-2000000, 2000000);
    std::vector<int64_t> t;
    std::vector<CameraPose> poses;
    int64_t now = 1341847980722988123;  // not a whole microsecond: rounded on writing
    for (int i = 0; i < 200; ++i) {
        Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
        q.normalize();
        CameraPose p;
        p.R_CtoW = q.toRotationMatrix().cast<Scalar>();
        p.p_CinW = Eigen::Vector3d(pos(rng), pos(rng), pos(rng)).cast<Scalar>();
        poses.push_back(p);
        t.push_back(now);
        now += 33333333 + jitter(rng);
    }
    const fs::path file = tmp.path() / "traj.txt";
    auto w = writeTumTrajectory(file, t, poses);
    ASSERT_TRUE(w) << w.error().message;
    auto back = readTumTrajectory(file);
    ASSERT_TRUE(back) << back.error().message;
    ASSERT_EQ(back->size(), poses.size());
    for (std::size_t i = 0; i < poses.size(); ++i) {
        const int64_t us = (t[i] + 500) / 1000;
        EXPECT_EQ((*back)[i].first, us * 1000) << i;
        const double dp =
            ((*back)[i].second.p_CinW - poses[i].p_CinW).cast<double>().cwiseAbs().maxCoeff();
        EXPECT_LT(dp, kFloat ? 1e-4 : 1e-8) << i;
        EXPECT_LT(rotationError((*back)[i].second.R_CtoW, poses[i].R_CtoW.cast<double>()),
                  kFloat ? 1e-5 : 1e-8)
            << i;
    }
    // Only the file itself is left in the directory (no temporary).
    std::size_t entries = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(tmp.path())) {
        ++entries;
    }
    EXPECT_EQ(entries, 1U);
    // The first data line has the TUM layout: 8 fields, t with 6 decimals.
    const std::string text = readFile(file);
    EXPECT_NE(text.find("\n1341847980.722988 "), std::string::npos);

    // An empty trajectory is valid.
    const fs::path empty = tmp.path() / "empty.txt";
    ASSERT_TRUE(writeTumTrajectory(empty, {}, {}).ok());
    auto none = readTumTrajectory(empty);
    ASSERT_TRUE(none);
    EXPECT_TRUE(none->empty());
}

TEST(TrajectoryIo, WriteRejectsBadInputAndNamesTheFile) {
    TempDir tmp("traj_bad");
    const fs::path file = tmp.path() / "out.txt";
    std::vector<int64_t> t = {0, 1000, 2000};
    std::vector<CameraPose> poses(3);

    auto r = writeTumTrajectory(file, std::span(t).first(2), poses);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(r.error().message.find(file.string()), std::string::npos);

    t[2] = 1400;  // 1.4 us rounds to 1 us: equal to the previous line
    r = writeTumTrajectory(file, t, poses);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("microsecond"), std::string::npos) << r.error().message;
    t[2] = 2000;

    poses[1].p_CinW.x() = std::numeric_limits<Scalar>::quiet_NaN();
    r = writeTumTrajectory(file, t, poses);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("pose 1"), std::string::npos) << r.error().message;
    poses[1] = CameraPose{};
    poses[2].R_CtoW *= 2;
    r = writeTumTrajectory(file, t, poses);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("not a rotation"), std::string::npos) << r.error().message;
    poses[2] = CameraPose{};
    EXPECT_FALSE(fs::exists(file));

    const fs::path nowhere = tmp.path() / "no" / "such" / "dir" / "out.txt";
    r = writeTumTrajectory(nowhere, t, poses);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_NE(r.error().message.find(nowhere.string()), std::string::npos);

    // Overwrites an existing file atomically.
    writeFile(file, "old\n");
    ASSERT_TRUE(writeTumTrajectory(file, t, poses).ok());
    auto back = readTumTrajectory(file);
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(back->size(), 3U);

    auto missing = readTumTrajectory(tmp.path() / "absent.txt");
    ASSERT_FALSE(missing);
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
    EXPECT_NE(missing.error().message.find("absent.txt"), std::string::npos);
}

}  // namespace
}  // namespace scaled::drivers::dataset
