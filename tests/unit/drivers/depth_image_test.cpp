// loadDepthMetres (depth_image.h).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/depth_image.h>
#include <scaled/drivers/source/frame_source.h>

#include "dataset_test_util.h"
#include "shared_data.h"

namespace scaled::drivers::dataset {
namespace {

namespace fs = std::filesystem;
using core::ErrorCode;
using test::TempDir;
using test::tinyImage;
using test::writeFile;

// A 4x3 16-bit depth map: 0 (no reading), 1000, 5000 and 65535 units.
cv::Mat rawDepth() {
    cv::Mat d(3, 4, CV_16UC1, cv::Scalar(1000));
    d.at<uint16_t>(0, 0) = 0;
    d.at<uint16_t>(1, 2) = 5000;
    d.at<uint16_t>(2, 3) = 65535;
    return d;
}

source::Frame frameWithDepth(const fs::path& depth) {
    source::Frame f;
    f.id = 7;
    f.image_path = "rgb/7.png";
    f.depth_path = depth;
    return f;
}

TEST(DatasetDepth, ConvertsSixteenBitUnitsToMetres) {
    TempDir tmp("depth");
    const fs::path file = tmp.path() / "d.png";
    ASSERT_TRUE(cv::imwrite(file.string(), rawDepth()));
    source::SequenceInfo info;
    info.depth_scale_m = 0.001;  // millimetres
    auto m = loadDepthMetres(frameWithDepth(file), info);
    ASSERT_TRUE(m) << m.error().message;
    ASSERT_EQ(m->type(), CV_32FC1);
    ASSERT_EQ(m->size(), cv::Size(4, 3));
    EXPECT_EQ(m->at<float>(0, 0), 0.0F);  // no reading stays 0
    EXPECT_FLOAT_EQ(m->at<float>(0, 1), 1.0F);
    EXPECT_FLOAT_EQ(m->at<float>(1, 2), 5.0F);
    EXPECT_FLOAT_EQ(m->at<float>(2, 3), 65.535F);

    info.depth_scale_m = 1.0 / 5000.0;  // TUM RGB-D
    m = loadDepthMetres(frameWithDepth(file), info);
    ASSERT_TRUE(m);
    EXPECT_FLOAT_EQ(m->at<float>(1, 2), 1.0F);
}

TEST(DatasetDepth, ErrorsNameTheFrameOrTheFile) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("depth_bad");
    source::SequenceInfo info;
    info.depth_scale_m = 0.001;

    source::Frame none;
    none.id = 3;
    none.image_path = "rgb/3.png";
    auto r = loadDepthMetres(none, info);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_NE(r.error().message.find("frame 3 (rgb/3.png): no depth image"), std::string::npos)
        << r.error().message;

    const fs::path missing = tmp.path() / "missing.png";
    r = loadDepthMetres(frameWithDepth(missing), info);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_NE(r.error().message.find(missing.string()), std::string::npos) << r.error().message;

    const fs::path eight = tmp.path() / "eight.png";
    ASSERT_TRUE(cv::imwrite(eight.string(), cv::Mat(3, 4, CV_8UC1, cv::Scalar(9))));
    r = loadDepthMetres(frameWithDepth(eight), info);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kParse);
    EXPECT_NE(r.error().message.find(eight.string() + ": expected a 16-bit single-channel"),
              std::string::npos)
        << r.error().message;

    const fs::path color16 = tmp.path() / "color16.png";
    ASSERT_TRUE(cv::imwrite(color16.string(), cv::Mat(3, 4, CV_16UC3, cv::Scalar(1, 2, 3))));
    r = loadDepthMetres(frameWithDepth(color16), info);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kParse);
    EXPECT_NE(r.error().message.find("3 channel(s)"), std::string::npos) << r.error().message;

    const fs::path corrupt = tmp.path() / "corrupt.png";
    writeFile(corrupt, "\x89PNG\r\n\x1a\n broken");
    r = loadDepthMetres(frameWithDepth(corrupt), info);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find(corrupt.string()), std::string::npos) << r.error().message;

    const fs::path good = tmp.path() / "good.png";
    ASSERT_TRUE(cv::imwrite(good.string(), rawDepth()));
    source::SequenceInfo no_scale;
    r = loadDepthMetres(frameWithDepth(good), no_scale);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("no depth scale"), std::string::npos) << r.error().message;
}

TEST(DatasetDepth, WorksThroughATumDepthList) {
    TempDir tmp("depth_tum");
    const fs::path& dir = tmp.path();
    fs::create_directories(dir / "rgb");
    fs::create_directories(dir / "depth");
    ASSERT_TRUE(cv::imwrite((dir / "rgb" / "0.png").string(), tinyImage(0)));
    cv::Mat d(6, 8, CV_16UC1, cv::Scalar(10000));  // 2 m at 5000 units per metre
    ASSERT_TRUE(cv::imwrite((dir / "depth" / "0.png").string(), d));
    writeFile(dir / "rgb.txt", "0.0 rgb/0.png\n");
    writeFile(dir / "depth.txt", "0.001 depth/0.png\n");
    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    auto m = loadDepthMetres(f, (*src)->info());
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_FLOAT_EQ(m->at<float>(3, 4), 2.0F);
}

TEST(DatasetDepth, RedkitchenFrameZeroHasPlausibleMetricDepth) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    auto m = loadDepthMetres(f, (*src)->info());
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_EQ(m->size(), cv::Size(640, 480));
    std::vector<float> valid;
    for (int r = 0; r < m->rows; ++r) {
        for (int c = 0; c < m->cols; ++c) {
            const float v = m->at<float>(r, c);
            if (v > 0) {
                valid.push_back(v);
            }
        }
    }
    // Most pixels have a reading; a kitchen seen from a handheld Kinect is
    // between about half a metre and a few metres away.
    EXPECT_GT(valid.size(), static_cast<std::size_t>(m->total() / 2));
    ASSERT_FALSE(valid.empty());
    std::nth_element(valid.begin(), valid.begin() + static_cast<std::ptrdiff_t>(valid.size() / 2),
                     valid.end());
    const float median = valid[valid.size() / 2];
    std::cout << "[ depth    ] redkitchen frame 0: median depth " << median << " m over "
              << valid.size() << " pixels\n";
    EXPECT_GT(median, 0.4F);
    EXPECT_LT(median, 4.0F);
}

}  // namespace
}  // namespace scaled::drivers::dataset
