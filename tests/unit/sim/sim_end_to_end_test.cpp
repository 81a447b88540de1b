// The whole pipeline on the sim source: the tracker (daemon defaults) on the
// rendered frames, the sim detector and the scale estimator every 10th frame
// of the map, against the true scale of the map (Sim(3) alignment of the SLAM
// camera centres with the ground truth). Two estimators see the same run: the
// daemon's defaults (estimator.model = "object") and the same with priors that
// know the sim's objects. Figures: docs/sim.md ("End to end"); the run's seed
// from SCALED_SIM_SEED, every update printed with SCALED_SIM_E2E_UPDATES=1.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/vision/mono_tracker.h>

#include "sim_priors.h"

namespace scaled::drivers::sim {
namespace {

using core::Vec3;

// One scale update of one estimator.
struct Update {
    int frame = 0;
    core::ScaleState state = core::ScaleState::kNoData;
    double map = 0;
    double lo = 0;  // ci95
    double hi = 0;
    int objects_used = 0;
    std::optional<double> truth;  // true scale of the map so far
};

// One estimator's record over the run.
struct EstimatorRun {
    std::vector<Update> updates;
    std::optional<int> converged_frame;  // first frame of the final converged run
    core::ScaleSummary final;
    std::string objects;  // the final object table, printable
};

struct EndToEnd {
    int frames = 0;
    int epochs = 1;
    int lost_frames = 0;
    std::vector<EstimatorRun> runs;     // one per estimator
    std::optional<double> truth;        // true scale of the final map
    std::optional<double> truth_first;  // over the final map's first and last 300 frames
    std::optional<double> truth_last;
    double render_ms = 0;    // per frame, thread CPU time
    double tracker_ms = 0;   // per frame
    double detector_ms = 0;  // per detection
};

// CPU time of the calling thread, ms (the machine may be shared: wall time varies).
double threadCpuMs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::optional<double> truthScale(std::span<const Vec3> est, std::span<const Vec3> gt) {
    if (est.size() < 3) {
        return std::nullopt;
    }
    auto a = core::alignTrajectories(est, gt, true);
    return a ? std::optional<double>(static_cast<double>(a->scale)) : std::nullopt;
}

// An estimator's configuration and priors.
struct EstimatorSetup {
    core::EstimatorConfig config;
    core::PriorTable priors;
};

std::string objectTable(const core::ScaleEstimator& e) {
    std::string out;
    const core::ObjectEvidence* objects = e.objects();
    if (objects == nullptr) {
        return out;
    }
    const auto s = e.summary();
    char line[256];
    for (int k = 0; k < objects->activeCount(); ++k) {
        const core::ObjectSummary o = objects->summary(k, s);
        const auto& prior = e.priors().priors()[static_cast<std::size_t>(o.class_index)];
        std::snprintf(line, sizeof line,
                      "  object %d %-12s %-9s views %2d/%2d det %3d frames %4lld-%4lld local %.3f "
                      "anchor sigma %.0f%% height %.3f m [%.3f, %.3f]\n",
                      o.id, std::string(prior.className()).c_str(), core::toString(o.state),
                      o.views_used, o.views, o.detections, static_cast<long long>(o.first_frame),
                      static_cast<long long>(o.last_frame), static_cast<double>(o.local_estimate),
                      100 * static_cast<double>(o.anchor_rel_sigma),
                      static_cast<double>(o.height_m), static_cast<double>(o.height_ci95_m.lo),
                      static_cast<double>(o.height_ci95_m.hi));
        out += line;
    }
    std::snprintf(line, sizeof line, "  information limit of the ci95 width %.1f%%\n",
                  100 * static_cast<double>(e.informationLimitRelWidth95()));
    return out + line;
}

// The tracker (daemon defaults) over max_frames sim frames; every 10th frame
// of the map, the sim detector's boxes go to every estimator of `setups` with
// the same snapshot.
EndToEnd runEndToEnd(const SimConfig& config, int max_frames,
                     const std::vector<EstimatorSetup>& setups) {
    EndToEnd r;
    auto source = openSimSource(config);
    EXPECT_TRUE(source.ok()) << source.error().message;
    auto detector = createSimDetector(config);
    EXPECT_TRUE(detector.ok()) << detector.error().message;
    if (!source || !detector) {
        return r;
    }
    const daemon::PipelineConfig pc = daemon::defaultPipelineConfig();
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    EXPECT_TRUE(camera.ok());
    if (!camera) {
        return r;
    }
    auto tracker = drivers::vision::MonoTracker::create(*camera, pc.tracker);
    EXPECT_TRUE(tracker.ok()) << tracker.error().message;
    std::vector<core::ScaleEstimator> estimators;
    for (const auto& s : setups) {
        auto e = core::ScaleEstimator::create(s.config, s.priors, *camera);
        EXPECT_TRUE(e.ok()) << e.error().message;
        if (!e) {
            return r;
        }
        estimators.push_back(std::move(*e));
    }
    if (!tracker) {
        return r;
    }
    r.runs.resize(setups.size());

    using Clock = std::chrono::steady_clock;
    const auto ms = [](Clock::time_point a, Clock::time_point b) {
        return std::chrono::duration<double, std::milli>(b - a).count();
    };
    std::vector<core::slam::MapPoint> points;
    std::vector<core::MapFeature> features;
    std::vector<core::Detection> dets(64);
    drivers::detector::DetectionResult boxes;
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    int frames_in_map = 0;
    bool need_gravity = true;
    drivers::source::Frame frame;
    for (int i = 0; i < max_frames; ++i) {
        const double c0 = threadCpuMs();
        auto got = (*source)->next(frame);
        r.render_ms += threadCpuMs() - c0;
        const auto t1 = Clock::now();
        EXPECT_TRUE(got.ok() && *got);
        if (!got || !*got) {
            break;
        }
        ++r.frames;
        if (need_gravity) {
            tracker->setGravityDownC(*frame.gravity_down_C);
            need_gravity = false;
        }
        const auto stats = tracker->processFrame(frame.t_ns, frame.gray);
        r.tracker_ms += ms(t1, Clock::now());
        const bool ok = stats.health == core::slam::SlamHealth::kOk;
        if (ok && stats.new_map) {
            frames_in_map = 0;
        }
        if (!ok) {
            ++r.lost_frames;
            tracker->reset();
            for (auto& e : estimators) {
                e.reset();
            }
            need_gravity = true;
            ++r.epochs;
            est.clear();
            gt.clear();
            frames_in_map = 0;
            for (auto& run : r.runs) {
                run.updates.clear();
                run.converged_frame.reset();
            }
            continue;
        }
        ++frames_in_map;
        const auto& slam = tracker->filter();
        est.push_back(slam.pose().p_CinW);
        gt.push_back(frame.T_CtoW_gt->p_CinW);
        if (frames_in_map > 1 && (frames_in_map - 1) % pc.detection.every_frames == 0) {
            const auto t2 = Clock::now();
            auto det = (*detector)->detect(frame.color, frame.id, frame.t_ns, boxes);
            r.detector_ms += ms(t2, Clock::now());
            EXPECT_TRUE(det.ok());
            const std::size_t n = drivers::detector::toEstimatorDetections(boxes, dets);
            slam.mapPoints(points);
            features.clear();
            for (const auto& m : points) {
                features.push_back({m.p_FinW, m.P_FinW});
            }
            const core::FrameSnapshot snapshot{slam.pose(), slam.upW(), features, frame.id};
            const std::optional<double> truth = truthScale(est, gt);
            for (std::size_t k = 0; k < estimators.size(); ++k) {
                const core::UpdateStats u =
                    estimators[k].update(snapshot, std::span(dets.data(), n));
                const auto s = estimators[k].summary();
                EstimatorRun& run = r.runs[k];
                run.updates.push_back({static_cast<int>(frame.id), s.state,
                                       static_cast<double>(s.map), static_cast<double>(s.ci95.lo),
                                       static_cast<double>(s.ci95.hi), u.objects_used, truth});
                if (s.state == core::ScaleState::kConverged) {
                    if (!run.converged_frame) {
                        run.converged_frame = static_cast<int>(frame.id);
                    }
                } else {
                    run.converged_frame.reset();
                }
            }
        }
    }
    for (std::size_t k = 0; k < estimators.size(); ++k) {
        r.runs[k].final = estimators[k].summary();
        r.runs[k].objects = objectTable(estimators[k]);
    }
    r.truth = truthScale(est, gt);
    const std::size_t part = std::min<std::size_t>(est.size(), 300);
    r.truth_first = truthScale(std::span(est).first(part), std::span(gt).first(part));
    r.truth_last = truthScale(std::span(est).last(part), std::span(gt).last(part));
    if (r.frames > 0) {
        r.render_ms /= r.frames;
        r.tracker_ms /= r.frames;
    }
    const std::size_t updates = r.runs.empty() ? 0 : r.runs.front().updates.size();
    if (updates > 0) {
        r.detector_ms /= static_cast<double>(updates);
    }
    return r;
}

// Figures of one estimator's run against the truth.
struct Figures {
    double err = 0;                  // final MAP against the final map's true scale
    double rel_width95 = 0;          // final
    bool final_holds_truth = false;  // the final ci95 holds the final true scale
    std::optional<int> first_used;   // frame of the first update with a used object
    int updates_after = 0;           // updates from the first used object on
    int holding_after = 0;           // of which the ci95 held the truth of the map so far
    int converged_updates = 0;       // updates in state converged
    int converged_missing = 0;       // of which the ci95 did not hold the truth
    double max_abs_err_settled = 0;  // largest |MAP error| from kSettledFrame on
};

// 30 s at 30 fps; SCALED_SIM_SEED picks the sim's seed (default 1) for the
// figures of docs/sim.md.
constexpr int kFrames = 900;
// From 20 s on (three or four objects used in seeds 1 and 2), the MAP's error
// against the truth of the map so far is bounded.
constexpr int kSettledFrame = 600;

Figures figures(const EndToEnd& r, const EstimatorRun& run) {
    Figures f;
    const double truth = r.truth.value_or(0);
    f.err = static_cast<double>(run.final.map) / truth - 1;
    f.rel_width95 = static_cast<double>(run.final.rel_width95);
    f.final_holds_truth = static_cast<double>(run.final.ci95.lo) <= truth &&
                          truth <= static_cast<double>(run.final.ci95.hi);
    for (const Update& u : run.updates) {
        if (!f.first_used && u.objects_used > 0) {
            f.first_used = u.frame;
        }
        const bool holds = u.truth && u.lo <= *u.truth && *u.truth <= u.hi;
        if (f.first_used) {
            ++f.updates_after;
            f.holding_after += holds ? 1 : 0;
        }
        if (u.frame >= kSettledFrame && u.truth) {
            f.max_abs_err_settled = std::max(f.max_abs_err_settled, std::abs(u.map / *u.truth - 1));
        }
        if (u.state == core::ScaleState::kConverged) {
            ++f.converged_updates;
            f.converged_missing += holds ? 0 : 1;
        }
    }
    return f;
}

void print(const char* name, const EndToEnd& r, const EstimatorRun& run, const Figures& f) {
    std::printf(
        "sim end to end (%s): %d frames, %d map(s), %d lost, %zu updates; first used object at "
        "frame %d; converged (held to the end) from frame %d; MAP %.4f, true %.4f, error "
        "%+.2f%%, ci95 [%.4f, %.4f] width %.1f%% (holds the truth: %s); the ci95 held the truth "
        "of the map so far in %d of %d updates from the first used object on; largest |error| "
        "from frame %d on %.1f%%; %d converged updates, %d of them not holding the truth; true "
        "scale of the first / last 300 frames %.4f / %.4f\n%s",
        name, r.frames, r.epochs, r.lost_frames, run.updates.size(), f.first_used.value_or(-1),
        run.converged_frame.value_or(-1), static_cast<double>(run.final.map), r.truth.value_or(0),
        100 * f.err, static_cast<double>(run.final.ci95.lo), static_cast<double>(run.final.ci95.hi),
        100 * f.rel_width95, f.final_holds_truth ? "yes" : "no", f.holding_after, f.updates_after,
        kSettledFrame, 100 * f.max_abs_err_settled, f.converged_updates, f.converged_missing,
        r.truth_first.value_or(0), r.truth_last.value_or(0), run.objects.c_str());
    // SCALED_SIM_E2E_UPDATES=1: every update.
    if (std::getenv("SCALED_SIM_E2E_UPDATES") != nullptr) {
        for (const Update& u : run.updates) {
            std::printf("  frame %4d %-10s objects %d MAP %.4f ci95 [%.4f, %.4f] truth %.4f\n",
                        u.frame, core::toString(u.state), u.objects_used, u.map, u.lo, u.hi,
                        u.truth.value_or(0));
        }
    }
}

SimConfig e2eConfig() {
    SimConfig config;
    config.duration_s = static_cast<double>(kFrames) / config.fps;
    if (const char* seed = std::getenv("SCALED_SIM_SEED")) {
        config.seed = std::strtoull(seed, nullptr, 10);
    }
    return config;
}

class SimEndToEnd : public ::testing::Test {
protected:
    // One run of the tracker (about 5 s), two estimators on its snapshots: the
    // daemon's defaults, and the same with priors that know the sim's objects
    // and objects.map_rel_sigma = 0.
    static void SetUpTestSuite() {
        auto priors = drivers::priors::loadPriorsFile(SCALED_SOURCE_DIR "/config/priors.toml");
        ASSERT_TRUE(priors.ok()) << priors.error().message;
        auto exact = drivers::priors::parsePriors(test::kSimExactPriorsToml, "kSimExactPriorsToml");
        ASSERT_TRUE(exact.ok()) << exact.error().message;
        const daemon::PipelineConfig pc = daemon::defaultPipelineConfig();
        // The daemon's map_rel_sigma (0.1) stands for the real tracker's map,
        // whose geometry around the objects is shorter than its motion says
        // (docs/accuracy.md); the synthetic room's map has no such error of its
        // own (only the drift over the run, which the test measures).
        EstimatorSetup exact_setup{pc.estimator, std::move(*exact)};
        exact_setup.config.objects.map_rel_sigma = 0;
        std::vector<EstimatorSetup> setups;
        setups.push_back({pc.estimator, std::move(*priors)});
        setups.push_back(std::move(exact_setup));
        run_ = new EndToEnd(runEndToEnd(e2eConfig(), kFrames, setups));
        std::printf(
            "seed %llu: render %.2f ms/frame, tracker %.2f ms/frame, detector %.3f ms/call\n",
            static_cast<unsigned long long>(e2eConfig().seed), run_->render_ms, run_->tracker_ms,
            run_->detector_ms);
    }
    static void TearDownTestSuite() {
        delete run_;
        run_ = nullptr;
    }
    static EndToEnd* run_;
};
EndToEnd* SimEndToEnd::run_ = nullptr;

// The common promises of the object model on the sim: an object is used
// within 15 s (its anchor needs parallax), the 95% interval holds the true
// scale at the end and in (almost) every update from the first used object
// on, and no update claims "converged" with an interval that misses it.
void expectHonest(const EndToEnd& r, const EstimatorRun& run, const Figures& f) {
    ASSERT_TRUE(f.first_used.has_value()) << "no object was used in " << r.frames << " frames";
    EXPECT_LE(*f.first_used, 450);
    EXPECT_TRUE(f.final_holds_truth) << "final ci95 [" << run.final.ci95.lo << ", "
                                     << run.final.ci95.hi << "], truth " << *r.truth;
    EXPECT_GE(f.holding_after, (9 * f.updates_after + 9) / 10)
        << f.holding_after << " of " << f.updates_after << " updates held the truth";
    EXPECT_EQ(f.converged_missing, 0) << "of " << f.converged_updates << " converged updates";
}

// The daemon's defaults (generic class priors, map_rel_sigma 0.1): an honest,
// wide interval (57% / 54% wide at the end for seeds 1 / 2) that holds the
// truth in every update (64 of 64, 81 of 81), a MAP 1.6% / 3.9% off at the end
// and at most 2.5% / 6.6% off from frame 600 on. Not converged, by design
// (docs/method.md, "Object-level evidence").
TEST_F(SimEndToEnd, DefaultsHoldTheTrueScale) {
    ASSERT_NE(run_, nullptr);
    ASSERT_EQ(run_->frames, kFrames);
    ASSERT_TRUE(run_->truth.has_value());
    ASSERT_EQ(run_->runs.size(), 2U);
    const EstimatorRun& run = run_->runs[0];
    const Figures f = figures(*run_, run);
    print("defaults", *run_, run, f);
    expectHonest(*run_, run, f);
    EXPECT_LT(std::abs(f.err), 0.08);
    EXPECT_LT(f.max_abs_err_settled, 0.12);
}

// Priors that know the sim's objects (1% spread) and map_rel_sigma 0: the
// interval narrows to 31% / 24% (seeds 1 / 2) and still holds the truth in
// every update; the MAP is 0.2% / 2.1% off at the end, at most 4.0% / 4.6%
// from frame 600 on. It does not reach "converged" (95% width < 10%), and
// cannot with these four objects: each object keeps a common relative error
// of objects.object_rel_sigma (5%) besides its class's spread, so four objects
// allow 10.0% at best (informationLimitRelWidth95), and the anchors'
// depth uncertainty (9-49% of their distance after 30 s; the camera's loop is
// 1.2 m x 0.9 m, the objects 2.3-3.5 m away) widens every object further. The
// test asserts what holds instead.
TEST_F(SimEndToEnd, ExactPriorsNarrowTheIntervalAroundTheTrueScale) {
    ASSERT_NE(run_, nullptr);
    ASSERT_EQ(run_->frames, kFrames);
    ASSERT_TRUE(run_->truth.has_value());
    ASSERT_EQ(run_->runs.size(), 2U);
    const EstimatorRun& run = run_->runs[1];
    const Figures f = figures(*run_, run);
    print("exact priors, map_rel_sigma 0", *run_, run, f);
    expectHonest(*run_, run, f);
    EXPECT_LT(std::abs(f.err), 0.05);
    EXPECT_LT(f.max_abs_err_settled, 0.08);
    // Narrower than the defaults' interval (31% against 57%, 24% against 54%).
    EXPECT_LT(f.rel_width95, 0.75 * static_cast<double>(run_->runs[0].final.rel_width95));
}

}  // namespace
}  // namespace scaled::drivers::sim
