// Image folders and video files as frame sources (dataset_folder.h,
// dataset_video.h) and the format detection of openDataset().

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_folder.h>
#include <scaled/drivers/dataset/dataset_video.h>
#include <scaled/drivers/source/frame_source.h>

#include "dataset_test_util.h"
#include "shared_data.h"

namespace scaled::drivers::dataset {
namespace {

namespace fs = std::filesystem;
using core::ErrorCode;
using test::readFile;
using test::TempDir;
using test::tinyImage;
using test::writeFile;

bool anyNoteContains(const source::SequenceInfo& info, const std::string& text) {
    return std::any_of(info.notes.begin(), info.notes.end(),
                       [&](const std::string& n) { return n.find(text) != std::string::npos; });
}

// ---------------------------------------------------------------- natural order

TEST(DatasetFolder, NaturalOrderComparesDigitRunsAsNumbers) {
    EXPECT_TRUE(naturalLess("img2", "img10"));
    EXPECT_FALSE(naturalLess("img10", "img2"));
    EXPECT_TRUE(naturalLess("img9.png", "img10.png"));
    EXPECT_TRUE(naturalLess("x9y", "x10y"));
    EXPECT_TRUE(naturalLess("frame_1_b", "frame_2_a"));
    EXPECT_TRUE(naturalLess("a", "a1"));
    EXPECT_TRUE(naturalLess("a", "B"));  // case-insensitive
    EXPECT_TRUE(naturalLess("img", "IMG1"));
    EXPECT_FALSE(naturalLess("b", "b"));
    // Equal as numbers: ordered by bytes, and the order stays strict.
    EXPECT_NE(naturalLess("a01", "a1"), naturalLess("a1", "a01"));
    EXPECT_TRUE(naturalLess("0000000000000000000000099", "100"));  // longer than int64
    EXPECT_TRUE(isImageFileName("x.PNG"));
    EXPECT_TRUE(isImageFileName("x.Jpeg"));
    EXPECT_TRUE(isImageFileName("dir/x.tiff"));
    EXPECT_FALSE(isImageFileName("x.png.txt"));
    EXPECT_FALSE(isImageFileName("png"));
    EXPECT_FALSE(isImageFileName("x.gif"));
}

// ---------------------------------------------------------------- image folder

// img1.png .. with seed = the number in the name; plus files to ignore.
void makeFolder(const fs::path& dir, const std::vector<int>& numbers) {
    for (const int n : numbers) {
        ASSERT_TRUE(
            cv::imwrite((dir / ("img" + std::to_string(n) + ".png")).string(), tinyImage(n)));
    }
}

TEST(DatasetFolder, ReadsImagesInNaturalOrderAndIgnoresOtherFiles) {
    TempDir tmp("folder");
    const fs::path& dir = tmp.path();
    makeFolder(dir, {10, 2, 1, 20});
    // Upper-case extensions count; other files, folders and hidden files do not.
    ASSERT_TRUE(cv::imwrite((dir / "img3.PNG").string(), tinyImage(3)));
    writeFile(dir / "notes.txt", "not an image\n");
    writeFile(dir / "img4.png.bak", "x");
    ASSERT_TRUE(cv::imwrite((dir / ".img0.png").string(), tinyImage(0)));
    fs::create_directories(dir / "img5.png");
    fs::create_directories(dir / "sub");
    ASSERT_TRUE(cv::imwrite((dir / "sub" / "img6.png").string(), tinyImage(6)));

    auto src = openDataset(dir);
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.frame_count, 5U);
    EXPECT_EQ(info.listed_count, 5U);
    EXPECT_FALSE(info.has_intrinsics);
    EXPECT_TRUE(anyNoteContains(info, "no intrinsics"));
    EXPECT_TRUE(anyNoteContains(info, "30 Hz"));
    EXPECT_FALSE(info.gravity_down_W.has_value());
    EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.0);

    const std::vector<int> order = {1, 2, 3, 10, 20};
    source::Frame f;
    for (std::size_t i = 0; i < order.size(); ++i) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        ASSERT_TRUE(*r);
        EXPECT_EQ(f.id, static_cast<int64_t>(i));
        EXPECT_EQ(f.image_path.stem(), "img" + std::to_string(order[i]));
        EXPECT_EQ(cv::norm(f.color, tinyImage(order[i]), cv::NORM_INF), 0.0);
        EXPECT_EQ(f.gray.type(), CV_8UC1);
        // Default 30 Hz.
        EXPECT_EQ(f.t_ns, std::llround(static_cast<double>(i) * 1e9 / 30.0));
        EXPECT_FALSE(f.T_CtoW_gt.has_value());
        EXPECT_FALSE(f.depth_path.has_value());
    }
    auto end = (*src)->next(f);
    ASSERT_TRUE(end);
    EXPECT_FALSE(*end);
    // Seek back.
    auto s = (*src)->seek(3);
    ASSERT_TRUE(s && *s);
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_EQ(f.image_path.stem(), "img10");
    EXPECT_FALSE((*src)->seek(6).ok());
}

TEST(DatasetFolder, FpsOptionSetsTheTimestampsAndIsValidated) {
    TempDir tmp("folder_fps");
    makeFolder(tmp.path(), {0, 1, 2});
    DatasetOptions opt;
    opt.folder_fps = 10;
    auto src = openDataset(tmp.path(), opt);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE((*src)->next(f).ok());
        EXPECT_EQ(f.t_ns, int64_t{100000000} * i);
    }
    for (const double bad :
         {0.0, -5.0, std::nan(""), std::numeric_limits<double>::infinity(), 2e9}) {
        opt.folder_fps = bad;
        auto r = openDataset(tmp.path(), opt);
        ASSERT_FALSE(r) << bad;
        EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
        EXPECT_NE(r.error().message.find("folder_fps"), std::string::npos) << r.error().message;
    }
}

TEST(DatasetFolder, TimesFileGivesTheTimestamps) {
    TempDir tmp("folder_times");
    makeFolder(tmp.path(), {1, 2, 10});
    writeFile(tmp.path() / "times.txt", "# seconds\n1.5\n1.6\n1.75\n");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_FALSE(anyNoteContains((*src)->info(), "Hz"));
    source::Frame f;
    const int64_t expected[] = {1500000000, 1600000000, 1750000000};
    for (const int64_t t : expected) {
        ASSERT_TRUE((*src)->next(f).ok());
        EXPECT_EQ(f.t_ns, t);
    }

    // More times than images: the extra ones are unused, with a note.
    writeFile(tmp.path() / "times.txt", "0\n1\n2\n3\n");
    auto more = openDataset(tmp.path());
    ASSERT_TRUE(more) << more.error().message;
    EXPECT_TRUE(anyNoteContains((*more)->info(), "extra times"));

    // Fewer: an error naming times.txt.
    writeFile(tmp.path() / "times.txt", "0\n1\n");
    auto fewer = openDataset(tmp.path());
    ASSERT_FALSE(fewer);
    EXPECT_NE(fewer.error().message.find((tmp.path() / "times.txt").string() + ": has 2 times"),
              std::string::npos)
        << fewer.error().message;

    // Same line rules as KITTI's times.txt.
    writeFile(tmp.path() / "times.txt", "0\n0.1\n0.1\n");
    auto dup = openDataset(tmp.path());
    ASSERT_FALSE(dup);
    EXPECT_NE(dup.error().message.find("times.txt:3: timestamp does not increase"),
              std::string::npos)
        << dup.error().message;
    writeFile(tmp.path() / "times.txt", "0\nx\n0.2\n");
    auto nan = openDataset(tmp.path());
    ASSERT_FALSE(nan);
    EXPECT_NE(nan.error().message.find("times.txt:2:"), std::string::npos) << nan.error().message;
}

TEST(DatasetFolder, CameraFileAndIntrinsicsOverride) {
    TempDir tmp("folder_camera");
    makeFolder(tmp.path(), {0, 1});
    writeFile(tmp.path() / "camera.txt", "# w h fx fy cx cy\n8 6 10 11 4 3\n");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    ASSERT_TRUE((*src)->info().has_intrinsics);
    EXPECT_DOUBLE_EQ(static_cast<double>((*src)->info().intrinsics.fy), 11.0);
    EXPECT_EQ((*src)->info().intrinsics.width_px, 8);

    DatasetOptions opt;
    opt.intrinsics = core::CameraIntrinsics{20, 21, 4, 3, 0, 0, 0, 0};
    auto over = openDataset(tmp.path(), opt);
    ASSERT_TRUE(over) << over.error().message;
    EXPECT_DOUBLE_EQ(static_cast<double>((*over)->info().intrinsics.fx), 20.0);
    EXPECT_EQ((*over)->info().intrinsics.height_px, 6);  // from the first image

    // A camera.txt for another image size: next() says so, naming the image.
    writeFile(tmp.path() / "camera.txt", "16 12 10 11 8 6\n");
    auto wrong = openDataset(tmp.path());
    ASSERT_TRUE(wrong) << wrong.error().message;
    source::Frame f;
    auto r = (*wrong)->next(f);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("img0.png: image is 8x6"), std::string::npos)
        << r.error().message;

    writeFile(tmp.path() / "camera.txt", "8 6 10 eleven 4 3\n");
    auto bad = openDataset(tmp.path());
    ASSERT_FALSE(bad);
    EXPECT_NE(bad.error().message.find("camera.txt:1: fy is not a number"), std::string::npos)
        << bad.error().message;
}

TEST(DatasetFolder, EmptyFolderIsAnErrorNamingIt) {
    TempDir tmp("folder_empty");
    writeFile(tmp.path() / "readme.txt", "no images here\n");
    fs::create_directories(tmp.path() / "frames.png");  // a directory, not an image
    auto direct = openImageFolder(tmp.path());
    ASSERT_FALSE(direct);
    EXPECT_EQ(direct.error().code, ErrorCode::kNotFound);
    EXPECT_NE(direct.error().message.find(tmp.path().string() + ": no images"), std::string::npos)
        << direct.error().message;

    auto detected = openDataset(tmp.path());
    ASSERT_FALSE(detected);
    EXPECT_NE(detected.error().message.find(tmp.path().string()), std::string::npos);
    EXPECT_NE(detected.error().message.find("not a dataset directory"), std::string::npos)
        << detected.error().message;

    DatasetOptions forced;
    forced.format = DatasetFormat::kImageFolder;
    auto missing = openDataset(tmp.path() / "nope", forced);
    ASSERT_FALSE(missing);
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
}

TEST(DatasetFolder, CorruptImageIsAnErrorOfNextNamingTheFile) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("folder_corrupt");
    makeFolder(tmp.path(), {0, 2});
    writeFile(tmp.path() / "img1.png", "\x89PNG\r\n\x1a\n not really");
    writeFile(tmp.path() / "img3.jpg", "");
    auto src = openDataset(tmp.path());
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, 4U);
    source::Frame f;
    ASSERT_TRUE((*src)->next(f).ok());
    auto r = (*src)->next(f);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kParse);
    EXPECT_NE(r.error().message.find((tmp.path() / "img1.png").string() + ": cannot decode"),
              std::string::npos)
        << r.error().message;
    r = (*src)->next(f);  // the cursor moved past the bad image
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.id, 2);
    r = (*src)->next(f);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("img3.jpg"), std::string::npos) << r.error().message;

    // An image deleted after opening: not found, naming it.
    auto again = openDataset(tmp.path());
    ASSERT_TRUE(again);
    fs::remove(tmp.path() / "img0.png");
    r = (*again)->next(f);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_NE(r.error().message.find("img0.png: image file not found"), std::string::npos)
        << r.error().message;
}

TEST(DatasetFolder, RedkitchenRgbFolderOpensAsAnImageFolder) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto src = openDataset(dir / "rgb");
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.name, "rgb");
    EXPECT_EQ(info.frame_count, 600U);
    EXPECT_FALSE(info.has_intrinsics);  // camera.txt is one level up
    source::Frame f;
    auto r = (*src)->next(f);
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.image_path.filename(), "000000.jpg");
    EXPECT_EQ(f.gray.cols, 640);
    EXPECT_EQ(f.gray.rows, 480);
    EXPECT_EQ(f.t_ns, 0);
    ASSERT_TRUE((*src)->seek(599).ok());
    r = (*src)->next(f);
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.image_path.filename(), "000599.jpg");
    EXPECT_EQ(f.t_ns, std::llround(599 * 1e9 / 30.0));

    // Same pixels as the TUM reader gives for that frame.
    auto tum = openDataset(dir);
    ASSERT_TRUE(tum);
    source::Frame g;
    ASSERT_TRUE((*tum)->seek(599).ok());
    ASSERT_TRUE((*tum)->next(g).ok());
    EXPECT_EQ(cv::norm(f.gray, g.gray, cv::NORM_INF), 0.0);
}

// ---------------------------------------------------------------- video

constexpr int kVideoFrames = 12;
constexpr double kVideoFps = 25.0;
const cv::Size kVideoSize(96, 64);

// Smooth content (JPEG-friendly): a gradient and a bright disc that moves.
cv::Mat videoFrame(int i) {
    cv::Mat img(kVideoSize, CV_8UC3);
    for (int r = 0; r < img.rows; ++r) {
        for (int c = 0; c < img.cols; ++c) {
            img.at<cv::Vec3b>(r, c) =
                cv::Vec3b(static_cast<uchar>(40 + c), static_cast<uchar>(60 + r),
                          static_cast<uchar>(100 + 8 * i));
        }
    }
    cv::circle(img, {12 + 6 * i, 32}, 9, cv::Scalar(250, 250, 250), -1, cv::LINE_AA);
    return img;
}

// Writes an MJPG .avi; fails the test when this OpenCV build cannot.
void writeVideo(const fs::path& file, int frames = kVideoFrames) {
    cv::VideoWriter writer(file.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), kVideoFps,
                           kVideoSize);
    ASSERT_TRUE(writer.isOpened()) << "cv::VideoWriter cannot write MJPG .avi on this OpenCV build";
    for (int i = 0; i < frames; ++i) {
        writer.write(videoFrame(i));
    }
    writer.release();
    ASSERT_TRUE(fs::is_regular_file(file));
}

double meanAbsDiff(const cv::Mat& a, const cv::Mat& b) {
    cv::Mat d;
    cv::absdiff(a, b, d);
    const cv::Scalar m = cv::mean(d);
    return (m[0] + m[1] + m[2]) / 3.0;
}

TEST(DatasetVideo, ReadsBackAnMjpgAviWithCountTimestampsPixelsAndSeek) {
    TempDir tmp("video");
    const fs::path file = tmp.path() / "clip.avi";
    writeVideo(file);

    auto src = openDataset(file);  // a regular file: detected as a video
    ASSERT_TRUE(src) << src.error().message;
    const source::SequenceInfo& info = (*src)->info();
    EXPECT_EQ(info.name, "clip.avi");
    EXPECT_EQ(info.frame_count, static_cast<std::size_t>(kVideoFrames));
    EXPECT_FALSE(info.has_intrinsics);

    std::vector<source::Frame> frames;
    source::Frame f;
    while (true) {
        auto r = (*src)->next(f);
        ASSERT_TRUE(r) << r.error().message;
        if (!*r) {
            break;
        }
        frames.push_back(f);
    }
    ASSERT_EQ(frames.size(), static_cast<std::size_t>(kVideoFrames));
    for (int i = 0; i < kVideoFrames; ++i) {
        const source::Frame& fr = frames[static_cast<std::size_t>(i)];
        EXPECT_EQ(fr.id, i);
        EXPECT_EQ(fr.image_path, file);
        EXPECT_EQ(fr.color.type(), CV_8UC3);
        EXPECT_EQ(fr.gray.type(), CV_8UC1);
        EXPECT_EQ(fr.color.size(), kVideoSize);
        // 25 Hz: 40 ms apart (container times or index / fps, both agree here).
        EXPECT_NEAR(static_cast<double>(fr.t_ns), i * 40e6, 1e6) << i;
        if (i > 0) {
            EXPECT_GT(fr.t_ns, frames[static_cast<std::size_t>(i - 1)].t_ns);
        }
        // MJPG is lossy: close, not equal; and closer to its own frame than to
        // the next one.
        const double own = meanAbsDiff(fr.color, videoFrame(i));
        EXPECT_LT(own, 4.0) << i;
        EXPECT_LT(own, meanAbsDiff(fr.color, videoFrame(i + 1))) << i;
    }
    // The end stays the end.
    auto r = (*src)->next(f);
    ASSERT_TRUE(r);
    EXPECT_FALSE(*r);

    // Seek back and forth: the same frame, pixels and timestamp as read in order.
    for (const std::size_t k : {5U, 2U, 9U, 0U, 11U}) {
        auto s = (*src)->seek(k);
        ASSERT_TRUE(s) << s.error().message;
        EXPECT_TRUE(*s);
        r = (*src)->next(f);
        ASSERT_TRUE(r && *r) << k;
        EXPECT_EQ(f.id, static_cast<int64_t>(k));
        EXPECT_EQ(f.t_ns, frames[k].t_ns) << k;
        EXPECT_EQ(cv::norm(f.color, frames[k].color, cv::NORM_INF), 0.0) << k;
    }
    // Reading on after a seek continues in order.
    ASSERT_TRUE((*src)->seek(10).ok());
    ASSERT_TRUE((*src)->next(f).ok());
    r = (*src)->next(f);
    ASSERT_TRUE(r && *r);
    EXPECT_EQ(f.id, 11);
    auto s = (*src)->seek(kVideoFrames);
    ASSERT_TRUE(s);
    EXPECT_FALSE(*s);
    r = (*src)->next(f);
    ASSERT_TRUE(r);
    EXPECT_FALSE(*r);
    s = (*src)->seek(kVideoFrames + 1);
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().code, ErrorCode::kInvalidArgument);
    s = (*src)->seek(1);
    ASSERT_TRUE(s && *s);
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_EQ(f.id, 1);
}

TEST(DatasetVideo, IntrinsicsFromCameraFileNextToTheVideoOrOptions) {
    TempDir tmp("video_camera");
    const fs::path file = tmp.path() / "clip.avi";
    writeVideo(file, 3);
    writeFile(tmp.path() / "camera.txt", "96 64 80 81 48 32\n");
    auto src = openDataset(file);
    ASSERT_TRUE(src) << src.error().message;
    ASSERT_TRUE((*src)->info().has_intrinsics);
    EXPECT_DOUBLE_EQ(static_cast<double>((*src)->info().intrinsics.fy), 81.0);

    DatasetOptions opt;
    opt.intrinsics = core::CameraIntrinsics{70, 70, 48, 32, 0, 0, 0, 0};
    auto over = openVideo(file, opt);
    ASSERT_TRUE(over) << over.error().message;
    EXPECT_DOUBLE_EQ(static_cast<double>((*over)->info().intrinsics.fx), 70.0);
    EXPECT_EQ((*over)->info().intrinsics.width_px, 96);  // from frame 0
    EXPECT_EQ((*over)->info().intrinsics.height_px, 64);

    // Intrinsics for another size: next() names the file and the frame.
    writeFile(tmp.path() / "camera.txt", "640 480 500 500 320 240\n");
    auto wrong = openDataset(file);
    ASSERT_TRUE(wrong) << wrong.error().message;
    source::Frame f;
    auto r = (*wrong)->next(f);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("clip.avi: frame 0: image is 96x64"), std::string::npos)
        << r.error().message;
}

TEST(DatasetVideo, UnreadableFilesAreIoErrorsNamingThem) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("video_bad");
    const fs::path text = tmp.path() / "notes.txt";
    writeFile(text, "this is not a video\n");
    auto r = openDataset(text);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_NE(r.error().message.find(text.string()), std::string::npos) << r.error().message;

    const fs::path fake = tmp.path() / "fake.avi";
    writeFile(fake, std::string("RIFF\x10\x00\x00\x00"
                                "AVI LIST garbage",
                                24));
    r = openVideo(fake);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find(fake.string()), std::string::npos) << r.error().message;

    r = openVideo(tmp.path() / "missing.avi");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);

    DatasetOptions video;
    video.format = DatasetFormat::kVideo;
    r = openDataset(tmp.path(), video);  // a directory is not a video
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find(tmp.path().string()), std::string::npos);

    const fs::path good = tmp.path() / "clip.avi";
    writeVideo(good, 2);
    DatasetOptions bad_fps;
    bad_fps.folder_fps = -1;
    r = openVideo(good, bad_fps);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
}

TEST(DatasetVideo, FrameThatFailsToDecodeNamesFileAndIndexAndReadingGoesOn) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    TempDir tmp("video_corrupt");
    const fs::path file = tmp.path() / "clip.avi";
    writeVideo(file, 8);
    // Blank out the JPEG data of frame 5 (the 6th start-of-image marker) up to
    // frame 6's chunk header.
    std::string bytes = readFile(file);
    std::vector<std::size_t> soi;
    for (std::size_t i = 0; i + 2 < bytes.size(); ++i) {
        if (static_cast<unsigned char>(bytes[i]) == 0xFF &&
            static_cast<unsigned char>(bytes[i + 1]) == 0xD8 &&
            static_cast<unsigned char>(bytes[i + 2]) == 0xFF) {
            soi.push_back(i);
        }
    }
    ASSERT_EQ(soi.size(), 8U);
    std::fill(bytes.begin() + static_cast<std::ptrdiff_t>(soi[5]),
              bytes.begin() + static_cast<std::ptrdiff_t>(soi[6] - 8), '\0');
    writeFile(file, bytes);

    auto src = openDataset(file);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    std::vector<int64_t> ids;
    std::vector<std::string> errors;
    std::optional<int64_t> prev_t;
    for (int guard = 0; guard < 20; ++guard) {
        auto r = (*src)->next(f);
        if (!r) {
            errors.push_back(r.error().message);
            continue;
        }
        if (!*r) {
            break;
        }
        ids.push_back(f.id);
        if (prev_t) {
            EXPECT_GT(f.t_ns, *prev_t);
        }
        prev_t = f.t_ns;
    }
    EXPECT_EQ(ids, (std::vector<int64_t>{0, 1, 2, 3, 4, 6, 7}));
    ASSERT_EQ(errors.size(), 1U);
    EXPECT_NE(errors[0].find(file.string() + ": frame 5: cannot decode"), std::string::npos)
        << errors[0];
    // Frame 6 keeps its own time (6 x 40 ms), not frame 5's.
    ASSERT_TRUE((*src)->seek(6).ok());
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_EQ(f.id, 6);
    EXPECT_NEAR(static_cast<double>(f.t_ns), 6 * 40e6, 1e6);
}

// ---------------------------------------------------------------- detection

TEST(DatasetOpen, DetectsFoldersAndVideosNextToTumAndKitti) {
    TempDir tmp("detect_new");
    // A directory with times.txt but no image_0/: an image folder timed by it.
    const fs::path folder = tmp.path() / "folder";
    fs::create_directories(folder);
    makeFolder(folder, {0, 1});
    writeFile(folder / "times.txt", "0\n0.5\n");
    auto src = openDataset(folder);
    ASSERT_TRUE(src) << src.error().message;
    source::Frame f;
    ASSERT_TRUE((*src)->seek(1).ok());
    ASSERT_TRUE((*src)->next(f).ok());
    EXPECT_EQ(f.t_ns, 500000000);

    // A folder with rgb.txt is TUM, even if it holds images.
    writeFile(folder / "rgb.txt", "0 img0.png\n");
    src = openDataset(folder);
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, 1U);
    // ... unless an image folder is asked for.
    DatasetOptions as_folder;
    as_folder.format = DatasetFormat::kImageFolder;
    src = openDataset(folder, as_folder);
    ASSERT_TRUE(src) << src.error().message;
    EXPECT_EQ((*src)->info().frame_count, 2U);
}

}  // namespace
}  // namespace scaled::drivers::dataset
