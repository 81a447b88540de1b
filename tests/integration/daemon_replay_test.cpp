// The daemon on real data: `scaled --source replay:redkitchen --pacing fast`
// with YOLOX-Nano, watched over its socket until the replay ends and the
// daemon exits (at_end = exit). Skips when ../shared (data or model) is absent.

#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

#include "daemon_harness.h"
#include "shared_data.h"
#include "slam_run.h"
#include "temp_dir.h"

namespace scaled::test {
namespace {

namespace fs = std::filesystem;

// The daemon replays redkitchen losslessly and exits at its end; with the
// object model (the default) its intervals hold the ground-truth scale
// (0.992 over the whole sequence, docs/accuracy.md) and it never claims a
// convergence that excludes it.
TEST(DaemonReplay, RedkitchenHoldsTheTruthAndExitsCleanly) {
    SCALED_REQUIRE_DATASET(dataset, "redkitchen");
    SCALED_REQUIRE_MODEL(model, "yolox_nano.onnx");
    TempDir tmp("d");
    DaemonUnderTest daemon(SCALED_BIN, tmp.path());
    writeFile(
        daemon.paths().config,
        daemonConfigText(daemon.paths(), fs::path(SCALED_SOURCE_DIR) / "config" / "priors.toml"));
    DaemonOptions opt;
    opt.args = {
        "--source", "replay:" + dataset.string(), "--pacing", "fast",
        "--set",    "source.at_end=exit",         "--set",    "detector.model=" + model.string(),
        "--set",    "socket.pose_rate_hz=0"};
    opt.ready_timeout = Millis(60'000);
    ASSERT_TRUE(daemon.start(opt));

    auto c = daemon.client();
    ASSERT_TRUE(c.has_value()) << "no VERSION greeting";
    ASSERT_TRUE(c->send(Json{{"cmd", "watch"}, {"enable", true}, {"pose", true}}));
    constexpr double kTruth = 0.992;
    // |position_map| of every POSE received, by frame (a slow reader gets the
    // latest only: not necessarily every frame).
    std::map<std::int64_t, double> pose_norm;
    std::optional<Json> first_evidence;
    std::optional<Json> last;
    std::optional<Json> status;
    std::int64_t last_frame = -1;
    int with_evidence = 0;
    int holding_truth = 0;
    // The daemon closes the connection when it exits at the end of the replay.
    const auto deadline = Clock::now() + Millis(900'000);
    while (true) {
        auto j = c->readJson(Millis(msLeft(deadline)));
        if (!j) {
            break;
        }
        ASSERT_TRUE(j->is_object()) << c->lastLine();
        if ((*j)["class"] == "STATUS") {
            status = j;
            continue;
        }
        if ((*j)["class"] == "POSE") {
            if ((*j)["epoch"] == 1) {
                const auto& p = (*j)["position_map"];
                pose_norm[(*j)["frame_id"].get<std::int64_t>()] =
                    std::hypot(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
            }
            continue;
        }
        if ((*j)["class"] != "SCALE") {
            continue;
        }
        EXPECT_GE((*j)["frame_id"].get<std::int64_t>(), last_frame);
        last_frame = (*j)["frame_id"].get<std::int64_t>();
        if ((*j)["observations"].get<std::int64_t>() > 0 && (*j)["ci95"].is_array()) {
            const double lo = (*j)["ci95"][0].get<double>();
            const double hi = (*j)["ci95"][1].get<double>();
            const bool holds = lo <= kTruth && kTruth <= hi;
            // The truth of the map so far moves until the path is long (1.13
            // at frame 70, within 3% of 0.992 from frame 300 on): counted from there.
            if (last_frame >= 300) {
                ++with_evidence;
                holding_truth += holds ? 1 : 0;
            }
            // Never a converged claim that excludes the truth.
            EXPECT_TRUE(holds || (*j)["state"] != "converged") << j->dump();
            if (!first_evidence) {
                first_evidence = j;
                ASSERT_TRUE(c->send(Json{{"cmd", "status"}}));
            }
        }
        last = j;
    }
    ASSERT_TRUE(c->eof()) << "the replay did not end within 900 s";
    const auto code = daemon.process().wait(Millis(60'000));
    ASSERT_TRUE(code.has_value()) << "scaled did not exit after the end of the replay";
    EXPECT_EQ(*code, 0);
    EXPECT_TRUE(daemon.notify().waitFor("STOPPING=1", Millis(0))) << daemon.notify().history();
    ASSERT_TRUE(first_evidence.has_value())
        << "no scale with evidence; last SCALE: " << (last ? last->dump() : std::string("none"));
    // Lossless: nothing dropped, every 10th frame detected after the map's first
    // 2 s (detection.min_map_age_s: 60 frames; a few may be in flight).
    ASSERT_TRUE(status.has_value()) << "no STATUS reply";
    EXPECT_EQ((*status)["frames"]["dropped"], 0) << status->dump();
    const auto tracked = (*status)["frames"]["tracked"].get<std::int64_t>();
    EXPECT_GE((*status)["detector"]["runs"].get<std::int64_t>(), (tracked - 60) / 10 - 3)
        << status->dump();
    EXPECT_EQ((*status)["detector"]["skipped"], 0) << status->dump();
    EXPECT_EQ((*status)["frames_total"].get<std::int64_t>(), 600) << status->dump();
    // Calibrated: the interval holds the truth (scale-eval: in every update).
    EXPECT_GE(holding_truth, with_evidence * 9 / 10) << holding_truth << " of " << with_evidence;
    // The last estimate, at the end of the sequence: the truth inside its
    // interval, the MAP within 15% (scale-eval, seed 1: 0.6% at the end).
    ASSERT_TRUE(last.has_value() && (*last)["ci95"].is_array()) << (last ? last->dump() : "");
    const double s = (*last)["scale"].get<double>();
    EXPECT_LE((*last)["ci95"][0].get<double>(), kTruth) << last->dump();
    EXPECT_GE((*last)["ci95"][1].get<double>(), kTruth) << last->dump();
    EXPECT_NEAR(s, kTruth, kTruth * 0.15) << last->dump();
    EXPECT_GT((*last)["observations"].get<std::int64_t>(),
              (*first_evidence)["observations"].get<std::int64_t>())
        << last->dump();
    EXPECT_FALSE(fs::exists(fs::symlink_status(daemon.paths().socket)));

    // The pose served is the tools' trajectory: slam-run's tracker (what
    // scale-eval runs) over the same frames with the daemon's tracker
    // configuration gives the same camera positions (compared by their
    // distance from the map's origin, which the gravity-aligned frame keeps).
    ASSERT_GT(pose_norm.size(), 100u) << "too few POSE lines";
    auto source = drivers::dataset::openDataset(dataset);
    ASSERT_TRUE(source.ok()) << source.error().message;
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    ASSERT_TRUE(camera.ok());
    tools::SlamRunOptions ro;
    ro.tracker = daemon::defaultPipelineConfig().tracker;
    const auto run = tools::runSlam(**source, *camera, ro);
    ASSERT_TRUE(run.ok()) << run.error().message;
    ASSERT_EQ(run->reinitialisations, 0);
    int compared = 0;
    double worst = 0;
    for (const auto& [frame, norm] : pose_norm) {
        if (frame < 0 || static_cast<std::size_t>(frame) >= run->poses.size()) {
            continue;
        }
        const double tool =
            static_cast<double>(run->poses[static_cast<std::size_t>(frame)].p_CinW.norm());
        worst = std::max(worst, std::abs(norm - tool) / (1e-3 + tool));
        ++compared;
    }
    std::printf("POSE vs slam-run: %d frames compared, worst relative difference %.3g\n", compared,
                worst);
    EXPECT_GT(compared, 100);
    EXPECT_LT(worst, 1e-5) << "the daemon's poses differ from slam-run's on " << compared
                           << " frames";
}

}  // namespace
}  // namespace scaled::test
