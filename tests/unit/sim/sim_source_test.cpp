// The daemon's `sim` source (drivers/sim): frames, the simulated detector and
// the configuration checks.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>

#include "sim_priors.h"

namespace scaled::drivers::sim {
namespace {

using core::Scalar;
using core::Vec2;
using core::Vec3;

std::unique_ptr<drivers::source::FrameSource> open(const SimConfig& config) {
    auto s = openSimSource(config);
    EXPECT_TRUE(s.ok()) << s.error().message;
    return s ? std::move(*s) : nullptr;
}

std::unique_ptr<drivers::detector::ObjectDetector> detectorFor(const SimConfig& config) {
    auto d = createSimDetector(config);
    EXPECT_TRUE(d.ok()) << d.error().message;
    return d ? std::move(*d) : nullptr;
}

bool sameBytes(const cv::Mat& a, const cv::Mat& b) {
    return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

std::optional<Vec2> projectW(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                             const Vec3& p_W) {
    const Vec3 p_C = pose.R_CtoW.transpose() * (p_W - pose.p_CinW);
    if (p_C.z() <= 0) {
        return std::nullopt;
    }
    return cam.project(p_C);
}

TEST(SimSource, FramesHaveTheConfiguredFormatTimesAndGravity) {
    SimConfig config;
    config.duration_s = 1.0;
    config.fps = 20.0;
    auto src = open(config);
    ASSERT_NE(src, nullptr);
    const auto& info = src->info();
    EXPECT_EQ(info.name, "sim");
    EXPECT_TRUE(info.has_intrinsics);
    EXPECT_EQ(info.intrinsics.width_px, 320);
    EXPECT_EQ(info.intrinsics.height_px, 240);
    // About 66 degrees of horizontal field of view.
    const double hfov = 2 * std::atan(160.0 / static_cast<double>(info.intrinsics.fx));
    EXPECT_NEAR(hfov * 180 / std::numbers::pi, 66.0, 0.01);
    EXPECT_EQ(info.frame_count, 20U);
    ASSERT_TRUE(info.gravity_down_W.has_value());
    EXPECT_TRUE(info.gravity_down_W->isApprox(Vec3(0, 0, -1)));

    drivers::source::Frame f;
    for (int i = 0; i < 20; ++i) {
        auto got = src->next(f);
        ASSERT_TRUE(got.ok() && *got) << i;
        EXPECT_EQ(f.id, i);
        EXPECT_EQ(f.t_ns, std::llround(i * 1e9 / 20.0));
        EXPECT_EQ(f.gray.type(), CV_8UC1);
        EXPECT_EQ(f.gray.cols, 320);
        EXPECT_EQ(f.gray.rows, 240);
        EXPECT_EQ(f.color.type(), CV_8UC3);
        ASSERT_TRUE(f.T_CtoW_gt.has_value());
        ASSERT_TRUE(f.gravity_down_C.has_value());
        const Vec3 down_W = f.T_CtoW_gt->R_CtoW * *f.gravity_down_C;
        EXPECT_TRUE(down_W.isApprox(Vec3(0, 0, -1), Scalar(1e-9)));
        // The camera looks roughly level: down is mostly along +y.
        EXPECT_GT(f.gravity_down_C->y(), 0.9);
        // Textured: the tracker needs contrast.
        cv::Scalar mean;
        cv::Scalar stddev;
        cv::meanStdDev(f.gray, mean, stddev);
        EXPECT_GT(stddev[0], 15.0);
        cv::Mat channels[3];
        cv::split(f.color, channels);
        EXPECT_TRUE(sameBytes(channels[0], f.gray));
        EXPECT_TRUE(sameBytes(channels[2], f.gray));
    }
    auto end = src->next(f);
    ASSERT_TRUE(end.ok());
    EXPECT_FALSE(*end);
}

TEST(SimSource, SameConfigGivesTheSameBytesAndSeedsDiffer) {
    SimConfig config;
    auto a = open(config);
    auto b = open(config);
    config.seed = 2;
    auto c = open(config);
    ASSERT_TRUE(a && b && c);
    drivers::source::Frame fa;
    drivers::source::Frame fb;
    drivers::source::Frame fc;
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE(a->next(fa).ok());
        ASSERT_TRUE(b->next(fb).ok());
        ASSERT_TRUE(c->next(fc).ok());
        EXPECT_TRUE(sameBytes(fa.gray, fb.gray)) << i;
        EXPECT_TRUE(fa.T_CtoW_gt->p_CinW == fb.T_CtoW_gt->p_CinW);
        EXPECT_FALSE(sameBytes(fa.gray, fc.gray)) << i;
    }
}

TEST(SimSource, UnboundedWhenDurationIsZeroAndSeekWorks) {
    SimConfig config;  // duration_s = 0: unbounded
    auto src = open(config);
    ASSERT_NE(src, nullptr);
    EXPECT_EQ(src->info().frame_count, 0U);
    auto s = src->seek(100000);  // an hour in: still frames
    ASSERT_TRUE(s.ok());
    EXPECT_TRUE(*s);
    drivers::source::Frame far;
    ASSERT_TRUE(src->next(far).ok());
    EXPECT_EQ(far.id, 100000);
    EXPECT_EQ(far.t_ns, std::llround(100000 * 1e9 / 30.0));

    // Seeking back gives the bytes of a fresh read.
    drivers::source::Frame first;
    ASSERT_TRUE(src->seek(7).ok());
    ASSERT_TRUE(src->next(first).ok());
    auto fresh = open(config);
    drivers::source::Frame f;
    for (int i = 0; i <= 7; ++i) {
        ASSERT_TRUE(fresh->next(f).ok());
    }
    EXPECT_EQ(first.id, 7);
    EXPECT_TRUE(sameBytes(first.gray, f.gray));

    // Bounded: frame_count is the end, beyond is an error.
    config.duration_s = 2.0;
    auto bounded = open(config);
    ASSERT_NE(bounded, nullptr);
    EXPECT_EQ(bounded->info().frame_count, 60U);
    auto at_end = bounded->seek(60);
    ASSERT_TRUE(at_end.ok());
    EXPECT_FALSE(*at_end);
    auto n = bounded->next(f);
    ASSERT_TRUE(n.ok());
    EXPECT_FALSE(*n);
    EXPECT_FALSE(bounded->seek(61).ok());
    ASSERT_TRUE(bounded->seek(59).ok());
    n = bounded->next(f);
    ASSERT_TRUE(n.ok() && *n);
    EXPECT_EQ(f.id, 59);
}

TEST(SimSource, ObjectsHaveThePriorMeansAndStandOnTheFloor) {
    const auto objects = simObjects(SimConfig{});
    ASSERT_GE(objects.size(), 4U);
    ASSERT_LE(objects.size(), 6U);
    for (const auto& o : objects) {
        EXPECT_EQ(o.box.min_m.z(), 0) << o.class_name;
        EXPECT_NEAR(static_cast<double>(o.box.max_m.z()), o.height_m, 1e-12) << o.class_name;
    }
    const auto find = [&](const std::string& name) {
        return std::find_if(objects.begin(), objects.end(),
                            [&](const SimObject& o) { return o.class_name == name; });
    };
    ASSERT_NE(find("refrigerator"), objects.end());
    EXPECT_DOUBLE_EQ(find("refrigerator")->height_m, 1.75);
    ASSERT_NE(find("chair"), objects.end());
    EXPECT_DOUBLE_EQ(find("chair")->height_m, 0.90);
    // Clear of the camera loop (which stays within 1.3 m of the room centre).
    auto traj = simPoseAt(SimConfig{}, 0);
    ASSERT_TRUE(traj.ok());
    for (int i = 0; i < 600; ++i) {
        const auto p = simPoseAt(SimConfig{}, std::llround(i * 1e8));
        ASSERT_TRUE(p.ok());
        for (const auto& o : objects) {
            EXPECT_FALSE(o.box.contains(p->p_CinW, Scalar(-0.5))) << o.class_name;
        }
    }
}

// The test priors that know the sim's objects (tests/support/sim_priors.h):
// one upright class per upright sim object, its mean the object's height.
TEST(SimSource, ExactTestPriorsAreTheObjectsHeights) {
    auto priors = drivers::priors::parsePriors(test::kSimExactPriorsToml, "kSimExactPriorsToml");
    ASSERT_TRUE(priors.ok()) << priors.error().message;
    int known = 0;
    for (const auto& o : simObjects(SimConfig{})) {
        const core::HeightPrior* p = priors->find(o.class_name);
        if (o.class_name == "dining table") {  // not upright: the estimator ignores it
            EXPECT_EQ(p, nullptr);
            continue;
        }
        ASSERT_NE(p, nullptr) << o.class_name;
        ++known;
        EXPECT_TRUE(p->upright()) << o.class_name;
        EXPECT_NEAR(static_cast<double>(p->mean()), o.height_m, 1e-3 * o.height_m) << o.class_name;
        EXPECT_NEAR(static_cast<double>(p->relativeSpread()), 0.01, 0.002) << o.class_name;
    }
    EXPECT_EQ(known, 4);
    EXPECT_EQ(priors->priors().size(), 4U);
}

// Every object is reported at some frames of the first loop, each box contains
// the projections of its object's top and bottom centres (front face), and the
// class names are the detector's.
TEST(SimDetector, BoxesContainTheProjectedObjects) {
    SimConfig config;
    config.miss_probability = 0;
    auto src = open(config);
    auto det = detectorFor(config);
    ASSERT_TRUE(src && det);
    const auto cam = core::PinholeRadialCamera::create(src->info().intrinsics).value();
    const auto objects = simObjects(config);
    const auto names = det->classNames();
    EXPECT_EQ(names.size(), objects.size());
    std::vector<int> seen(objects.size(), 0);
    drivers::source::Frame f;
    drivers::detector::DetectionResult r;
    const double jitter_margin = 5 * config.box_jitter_px;
    for (int i = 0; i < 450; i += 5) {  // 15 s: a whole loop
        ASSERT_TRUE(src->seek(static_cast<std::size_t>(i)).ok());
        ASSERT_TRUE(src->next(f).ok());
        auto ok = det->detect(f.color, f.id, f.t_ns, r);
        ASSERT_TRUE(ok.ok()) << ok.error().message;
        EXPECT_EQ(r.frame_id, f.id);
        EXPECT_EQ(r.t_ns, f.t_ns);
        EXPECT_EQ(r.width_px, 320);
        EXPECT_GE(r.timing.totalMs(), 0.0);
        for (const auto& d : r.detections) {
            ASSERT_GE(d.class_id, 0);
            ASSERT_LT(static_cast<std::size_t>(d.class_id), objects.size());
            EXPECT_EQ(d.class_name, names[static_cast<std::size_t>(d.class_id)]);
            const auto k = static_cast<std::size_t>(
                std::find_if(objects.begin(), objects.end(),
                             [&](const SimObject& o) { return o.class_name == d.class_name; }) -
                objects.begin());
            ++seen[k];
            EXPECT_FLOAT_EQ(d.score, config.score);
            EXPECT_GE(d.box.x_min_px, 0);
            EXPECT_LE(d.box.x_max_px, 319);
            EXPECT_LT(d.box.x_min_px, d.box.x_max_px);
            EXPECT_LT(d.box.y_min_px, d.box.y_max_px);
            // Top and bottom centres of the object's box (the vertical axis).
            const auto& b = objects[k].box;
            const Vec3 c = (b.min_m + b.max_m) / 2;
            for (const Scalar z : {b.min_m.z(), b.max_m.z()}) {
                const auto px = projectW(cam, *f.T_CtoW_gt, Vec3(c.x(), c.y(), z));
                ASSERT_TRUE(px.has_value());
                if (px->y() < 0 || px->y() > 239 || px->x() < 0 || px->x() > 319) {
                    continue;  // clipped part of a mostly visible object
                }
                EXPECT_GE(px->x(), d.box.x_min_px - jitter_margin) << d.class_name << " " << i;
                EXPECT_LE(px->x(), d.box.x_max_px + jitter_margin) << d.class_name << " " << i;
                EXPECT_GE(px->y(), d.box.y_min_px - jitter_margin) << d.class_name << " " << i;
                EXPECT_LE(px->y(), d.box.y_max_px + jitter_margin) << d.class_name << " " << i;
            }
        }
    }
    for (std::size_t k = 0; k < objects.size(); ++k) {
        EXPECT_GT(seen[k], 0) << objects[k].class_name << " never reported";
    }
}

TEST(SimDetector, SameFrameGivesTheSameBoxesAndMissesAreDrawn) {
    SimConfig config;
    auto a = detectorFor(config);
    auto b = detectorFor(config);
    ASSERT_TRUE(a && b);
    const cv::Mat image(240, 320, CV_8UC1, cv::Scalar(0));
    drivers::detector::DetectionResult ra;
    drivers::detector::DetectionResult rb;
    int reported = 0;
    for (int i = 0; i < 450; i += 3) {
        const std::int64_t t_ns = std::llround(i * 1e9 / 30.0);
        ASSERT_TRUE(a->detect(image, i, t_ns, ra).ok());
        ASSERT_TRUE(b->detect(image, i, t_ns, rb).ok());
        ASSERT_EQ(ra.detections.size(), rb.detections.size());
        for (std::size_t k = 0; k < ra.detections.size(); ++k) {
            EXPECT_EQ(ra.detections[k].box.x_min_px, rb.detections[k].box.x_min_px);
            EXPECT_EQ(ra.detections[k].box.y_max_px, rb.detections[k].box.y_max_px);
        }
        reported += static_cast<int>(ra.detections.size());
    }
    EXPECT_GT(reported, 50);
    // Every object missed: nothing is reported.
    config.miss_probability = 1;
    auto none = detectorFor(config);
    ASSERT_NE(none, nullptr);
    for (int i = 0; i < 450; i += 15) {
        ASSERT_TRUE(none->detect(image, i, std::llround(i * 1e9 / 30.0), ra).ok());
        EXPECT_TRUE(ra.detections.empty());
    }
}

// An object whose centre is out of view (behind the camera or beside the
// image) is not reported; the same object in view is, at other frames.
TEST(SimDetector, OutOfViewObjectsAreNotReported) {
    SimConfig config;
    config.miss_probability = 0;
    auto det = detectorFor(config);
    ASSERT_NE(det, nullptr);
    const auto objects = simObjects(config);
    const auto fridge = std::find_if(objects.begin(), objects.end(), [](const SimObject& o) {
        return o.class_name == "refrigerator";
    });
    ASSERT_NE(fridge, objects.end());
    // simPoseAt gives the trajectory; find a frame where the fridge is reported.
    const cv::Mat image(240, 320, CV_8UC1, cv::Scalar(0));
    drivers::detector::DetectionResult r;
    const auto has = [&](const drivers::detector::DetectionResult& res, const std::string& name) {
        return std::any_of(
            res.detections.begin(), res.detections.end(),
            [&](const drivers::detector::ObjectDetection& d) { return d.class_name == name; });
    };
    int with = 0;
    int without = 0;
    const auto cam = core::PinholeRadialCamera::create(simIntrinsics(config)).value();
    for (int i = 0; i < 450; ++i) {
        const std::int64_t t_ns = std::llround(i * 1e9 / 30.0);
        ASSERT_TRUE(det->detect(image, i, t_ns, r).ok());
        const auto pose = simPoseAt(config, t_ns).value();
        const Vec3 c = (fridge->box.min_m + fridge->box.max_m) / 2;
        const auto px = projectW(cam, pose, c);
        const bool centre_in_view =
            px && px->x() >= 0 && px->x() <= 319 && px->y() >= 0 && px->y() <= 239;
        if (has(r, "refrigerator")) {
            ++with;
            EXPECT_TRUE(centre_in_view) << i;
        } else if (!centre_in_view) {
            ++without;
        }
    }
    EXPECT_GT(with, 10);
    EXPECT_GT(without, 100);
}

// The visibility rule: requiring every sample point of the faces to be seen
// unoccluded and the whole box inside the image drops the partly hidden or
// clipped objects, so the reports can only become fewer.
TEST(SimDetector, StricterVisibilityReportsFewerObjects) {
    SimConfig config;
    config.miss_probability = 0;
    auto lenient = detectorFor(config);
    config.min_visible_fraction = 1.0;
    config.min_inside_fraction = 1.0;
    auto strict = detectorFor(config);
    ASSERT_TRUE(lenient && strict);
    const cv::Mat image(240, 320, CV_8UC1, cv::Scalar(0));
    drivers::detector::DetectionResult a;
    drivers::detector::DetectionResult b;
    int n_lenient = 0;
    int n_strict = 0;
    for (int i = 0; i < 450; i += 2) {
        const std::int64_t t_ns = std::llround(i * 1e9 / 30.0);
        ASSERT_TRUE(lenient->detect(image, i, t_ns, a).ok());
        ASSERT_TRUE(strict->detect(image, i, t_ns, b).ok());
        EXPECT_LE(b.detections.size(), a.detections.size());
        n_lenient += static_cast<int>(a.detections.size());
        n_strict += static_cast<int>(b.detections.size());
    }
    EXPECT_LT(n_strict, n_lenient);
}

TEST(SimDetector, RejectsImagesOfTheWrongSizeOrType) {
    auto det = detectorFor(SimConfig{});
    ASSERT_NE(det, nullptr);
    drivers::detector::DetectionResult r;
    EXPECT_FALSE(det->detect(cv::Mat(), 0, 0, r).ok());
    EXPECT_FALSE(det->detect(cv::Mat(240, 320, CV_32FC1, cv::Scalar(0)), 0, 0, r).ok());
    auto wrong = det->detect(cv::Mat(480, 640, CV_8UC3, cv::Scalar(0)), 0, 0, r);
    ASSERT_FALSE(wrong.ok());
    EXPECT_NE(wrong.error().message.find("640x480"), std::string::npos) << wrong.error().message;
    EXPECT_TRUE(det->detect(cv::Mat(240, 320, CV_8UC4, cv::Scalar(0)), 0, 0, r).ok());
}

TEST(SimConfigCheck, BadFieldsAreNamed) {
    struct Case {
        const char* field;
        void (*set)(SimConfig&);
    };
    const Case cases[] = {
        {"fps", [](SimConfig& c) { c.fps = 0; }},
        {"fps", [](SimConfig& c) { c.fps = 241; }},
        {"width_px", [](SimConfig& c) { c.width_px = 63; }},
        {"height_px", [](SimConfig& c) { c.height_px = 1081; }},
        {"duration_s", [](SimConfig& c) { c.duration_s = -1; }},
        {"duration_s", [](SimConfig& c) { c.duration_s = std::nan(""); }},
        {"hfov_deg", [](SimConfig& c) { c.hfov_deg = 10; }},
        {"pixel_noise", [](SimConfig& c) { c.pixel_noise = -1; }},
        {"box_jitter_px", [](SimConfig& c) { c.box_jitter_px = 100; }},
        {"miss_probability", [](SimConfig& c) { c.miss_probability = 1.5; }},
        {"score", [](SimConfig& c) { c.score = 0; }},
        {"min_inside_fraction", [](SimConfig& c) { c.min_inside_fraction = 0; }},
        {"min_visible_fraction", [](SimConfig& c) { c.min_visible_fraction = 2; }},
    };
    EXPECT_TRUE(validate(SimConfig{}).ok());
    for (const auto& tc : cases) {
        SimConfig c;
        tc.set(c);
        const auto v = validate(c);
        ASSERT_FALSE(v.ok()) << tc.field;
        EXPECT_EQ(v.error().code, core::ErrorCode::kInvalidArgument);
        EXPECT_NE(v.error().message.find(tc.field), std::string::npos) << v.error().message;
        auto src = openSimSource(c);
        ASSERT_FALSE(src.ok()) << tc.field;
        EXPECT_NE(src.error().message.find(tc.field), std::string::npos);
        auto det = createSimDetector(c);
        ASSERT_FALSE(det.ok()) << tc.field;
        EXPECT_NE(det.error().message.find(tc.field), std::string::npos);
    }
}

}  // namespace
}  // namespace scaled::drivers::sim
