// Steady-state tracking and scale updates do no heap allocation.
//
// The daemon's per-frame path (daemon/src/pipeline.cpp) without its threads:
// MonoTracker::processFrame on every frame; on every Nth frame of the map
// (detection.every_frames) the SLAM snapshot captured into pre-reserved
// storage, the frame's image copied into a reused buffer and both handed over
// by swap (tracking -> mailbox -> detection), the detections converted for
// the estimator and ScaleEstimator::update with the snapshot's view, then the
// log density read out as the daemon publishes it. After a warm-up, every
// allocation during those stages is counted: through the global operator new
// (allocation_counter.cpp) and, outside the sanitizers, through the C
// allocator too (malloc_counter.cpp: Eigen's dynamic matrices and
// cv::fastMalloc call malloc directly).
//
// Not counted: the frame source (the sim renderer makes a fresh image per
// frame, as a camera driver hands out new buffers) and the sim detector,
// a stand-in for the DNN. Their counts are printed for information.
//
// With estimator.model = "object" the same run also publishes the object
// table as the detection thread does after each update (collectObjects into
// storage reserved up front, ReportHub::publishObjects, an OBJECT field-log
// line per object the update saw) and, as the socket thread does, copies it
// out of the hub and encodes an OBJECTS reply.
//
// Every tracked frame also publishes its pose as the tracking thread does
// (makePoseReport from the filter, ReportHub::publishPose) and, as the socket
// thread does for a pose watcher, copies it out of the hub, passes it through
// the rate limiter and encodes the POSE line with the latest scale; and, as
// the field log does (LogEvents::onPose), thins them to log.pose_rate_hz and
// formats the POSE log line.
//
// The run happens once per model (SetUpTestSuite); the tests check its record:
//   WorkWasReal             one healthy map, features matched and added,
//                           estimator updates with observations that moved
//                           the posterior: a zero count is not vacuous;
//   NoOperatorNew           no operator new in any counted stage;
//   NoMalloc                no malloc either (Eigen's blocked solvers and
//                           cv::fastMalloc go around operator new; EkfSlam's
//                           update is written as plain loops for this).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/slam/slam_snapshot.h>
#include <scaled/daemon/log_service.h>
#include <scaled/daemon/pipeline.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/protocol.h>
#include <scaled/daemon/report.h>
#include <scaled/daemon/socket_service.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/vision/mono_tracker.h>

#include "allocation_counter.h"
#include "malloc_counter.h"

namespace scaled {
namespace {

// Warm-up: the map fills, every buffer meets its largest size class. Then the
// counted frames: 400 at 30 fps (13 s; the camera turns to new walls, so new
// features are initialised from corners all along).
constexpr int kWarmupFrames = 100;
constexpr int kCountedFrames = 400;

struct Counts {
    std::int64_t news = 0;     // global operator new
    std::int64_t mallocs = 0;  // malloc family (0 when not counted)
};

Counts countsNow() {
    return {test::allocationCount(), test::mallocCount()};
}

// Allocations of one stage of the per-frame path.
struct Stage {
    const char* name = "";
    bool asserted = true;  // false: reported only (frame source, detector stand-in)
    std::int64_t calls = 0;
    Counts total;
    std::int64_t frames_allocating = 0;
    std::int64_t first_frame = -1;  // first counted frame on which it allocated

    // Adds the allocations made since `before` by a call on `frame_id`.
    void add(const Counts& before, std::int64_t frame_id) {
        const Counts after = countsNow();
        const Counts d{after.news - before.news, after.mallocs - before.mallocs};
        ++calls;
        total.news += d.news;
        total.mallocs += d.mallocs;
        if (d.news != 0 || d.mallocs != 0) {
            ++frames_allocating;
            if (first_frame < 0) {
                first_frame = frame_id;
            }
        }
    }
    [[nodiscard]] bool allocated() const { return total.news != 0 || total.mallocs != 0; }
};

std::string report(std::span<const Stage> stages) {
    std::string s;
    for (const Stage& st : stages) {
        char line[256];
        std::snprintf(
            line, sizeof line,
            "  %-34s %5lld calls: %6lld operator new, %6lld malloc, on %lld frames "
            "(first: frame %lld)%s\n",
            st.name, static_cast<long long>(st.calls), static_cast<long long>(st.total.news),
            static_cast<long long>(st.total.mallocs), static_cast<long long>(st.frames_allocating),
            static_cast<long long>(st.first_frame), st.asserted ? "" : " [not asserted]");
        s += line;
    }
    return s;
}

// What the run did and what it allocated.
struct RunRecord {
    bool completed = false;  // every frame processed (no fatal failure on the way)
    std::array<Stage, 9> stages{};
    std::string table;
    int counted_frames = 0;
    int frames_not_ok = 0;
    int new_maps = 0;
    long long matched = 0;
    long long inliers = 0;
    int min_inliers = 1 << 30;
    int added = 0;
    int frames_adding = 0;
    int updates = 0;
    long long observations = 0;
    core::ScaleSummary before_summary;
    core::ScaleSummary after_summary;
    double log_p_change = 0;
    // The object table (model kObject): its largest size, the objects used
    // at the end, the OBJECT lines formatted and the OBJECTS replies' bytes.
    std::size_t max_objects_seen = 0;
    int objects_used = 0;
    int object_lines = 0;
    std::size_t objects_reply_bytes = 0;
    // POSE lines encoded (every counted frame) and those with a metric part.
    int pose_lines = 0;
    int metric_pose_lines = 0;
    // The field log's POSE lines (log.pose_rate_hz, the default) and those with a metric part.
    int pose_log_lines = 0;
    int metric_pose_log_lines = 0;
};

// The run; gtest assertions inside stop it early (completed stays false).
void runPipeline(RunRecord& rec, core::EstimatorModel model) {
    drivers::sim::SimConfig config;  // seed 1, 320 x 240, 30 fps: the daemon's sim defaults
    auto source = drivers::sim::openSimSource(config);
    ASSERT_TRUE(source.ok()) << source.error().message;
    auto detector = drivers::sim::createSimDetector(config);
    ASSERT_TRUE(detector.ok()) << detector.error().message;
    auto priors = drivers::priors::loadPriorsFile(SCALED_SOURCE_DIR "/config/priors.toml");
    ASSERT_TRUE(priors.ok()) << priors.error().message;
    daemon::PipelineConfig pc = daemon::defaultPipelineConfig();
    pc.estimator.model = model;
    if (model == core::EstimatorModel::kObject) {
        // The sim's camera mostly turns: looser anchors so that objects are
        // used (and their heights computed) within the run.
        pc.estimator.objects.max_anchor_rel_sigma = core::Scalar(0.6);
        pc.estimator.objects.min_parallax_deg = 1;
    }
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    ASSERT_TRUE(camera.ok());
    auto tracker = drivers::vision::MonoTracker::create(*camera, pc.tracker);
    ASSERT_TRUE(tracker.ok()) << tracker.error().message;
    auto estimator = core::ScaleEstimator::create(pc.estimator, *priors, *camera);
    ASSERT_TRUE(estimator.ok()) << estimator.error().message;

    // What the daemon sets up before its threads run.
    const int max_features = pc.tracker.slam.max_features;
    core::slam::SlamSnapshot staging;  // tracking thread
    core::slam::SlamSnapshot pending;  // the mailbox
    core::slam::SlamSnapshot job;      // detection thread
    ASSERT_TRUE(staging.reserve(max_features).ok());
    ASSERT_TRUE(pending.reserve(max_features).ok());
    ASSERT_TRUE(job.reserve(max_features).ok());
    cv::Mat staging_image;
    cv::Mat pending_image;
    cv::Mat job_image;
    drivers::detector::DetectionResult boxes;
    std::vector<core::Detection> dets(
        static_cast<std::size_t>(std::max(1, pc.detector.max_detections)));
    std::vector<core::ObservationRecord> records(512);
    std::vector<double> log_p_out(estimator->posterior().logDensity().size());
    // The object table's storage (Pipeline::create, ReportHub, the socket
    // thread's copy and reply buffer, the log's line buffer).
    const std::size_t table_size =
        estimator->objects() != nullptr ? estimator->objects()->capacity() : 0;
    daemon::ReportHub hub(log_p_out.size());
    hub.setObjectModel(model, table_size);
    daemon::ObjectsSnapshot objects;
    objects.model = model;
    objects.objects.reserve(table_size);
    daemon::ObjectsSnapshot socket_copy;
    socket_copy.objects.reserve(table_size);
    std::string reply;
    reply.reserve(1 << 16);
    std::string log_line;
    log_line.reserve(8192);
    // The socket thread's POSE line and the scale it combines it with.
    std::string pose_line;
    pose_line.reserve(2048);
    daemon::ScaleReport scale_report;
    scale_report.epoch = 1;
    daemon::PoseRateLimiter pose_limiter(0);  // every pose, as with pose_rate_hz = 0
    daemon::PoseRateLimiter log_pose_limiter(daemon::LogConfig{}.pose_rate_hz);
    const int every = pc.detection.every_frames;
    ASSERT_GT(every, 0);

    std::array<Stage, 9>& stages = rec.stages;
    Stage& track = stages[0];
    Stage& capture = stages[1];
    Stage& convert = stages[2];
    Stage& update = stages[3];
    Stage& source_stage = stages[4];
    Stage& detect_stage = stages[5];
    Stage& table_stage = stages[6];
    Stage& reply_stage = stages[7];
    Stage& pose_stage = stages[8];
    pose_stage.name = "pose: report, hub, POSE line, POSE log line";
    table_stage.name = "object table: collect, hub, OBJECT lines";
    reply_stage.name = "OBJECTS reply (socket thread)";
    track.name = "MonoTracker::processFrame";
    capture.name = "snapshot capture + image hand-over";
    convert.name = "toEstimatorDetections";
    update.name = "ScaleEstimator::update + readout";
    source_stage.name = "sim source next()";
    source_stage.asserted = false;
    detect_stage.name = "sim detector detect()";
    detect_stage.asserted = false;

    // Evidence that the counted frames did real work.
    int& counted_frames = rec.counted_frames;
    int& frames_not_ok = rec.frames_not_ok;
    int& new_maps = rec.new_maps;
    long long& matched = rec.matched;
    long long& inliers = rec.inliers;
    int& min_inliers = rec.min_inliers;
    int& added = rec.added;
    int& frames_adding = rec.frames_adding;
    int& updates = rec.updates;
    long long& observations = rec.observations;
    core::ScaleSummary& before_summary = rec.before_summary;
    std::vector<double> log_p_before;

    drivers::source::Frame frame;
    std::int64_t frames_in_map = 0;
    for (int i = 0; i < kWarmupFrames + kCountedFrames; ++i) {
        const bool counting = i >= kWarmupFrames;
        if (i == kWarmupFrames) {
            before_summary = estimator->summary();
            const auto lp = estimator->posterior().logDensity();
            log_p_before.assign(lp.begin(), lp.end());
        }
        Counts c0 = countsNow();
        auto got = (*source)->next(frame);
        if (counting) {
            source_stage.add(c0, frame.id);
        }
        ASSERT_TRUE(got.ok() && *got) << "frame " << i;
        if (i == 0) {
            ASSERT_TRUE(frame.gravity_down_C.has_value());
            tracker->setGravityDownC(*frame.gravity_down_C);
        }

        c0 = countsNow();
        const drivers::vision::TrackStats stats = tracker->processFrame(frame.t_ns, frame.gray);
        if (counting) {
            track.add(c0, frame.id);
        }
        const bool ok = stats.health == core::slam::SlamHealth::kOk;
        // A re-initialisation would make the run a different test: the seeded
        // run tracks one map throughout; fail loudly rather than recover.
        ASSERT_TRUE(ok) << "frame " << frame.id << ": tracking lost ("
                        << core::slam::toString(stats.health) << ")";
        if (stats.new_map) {
            frames_in_map = 0;
        }
        ++frames_in_map;
        if (counting) {
            ++counted_frames;
            frames_not_ok += ok ? 0 : 1;
            new_maps += stats.new_map ? 1 : 0;
            matched += stats.matched;
            inliers += stats.inliers + stats.rescued;
            min_inliers = std::min(min_inliers, stats.inliers + stats.rescued);
            added += stats.added;
            frames_adding += stats.added > 0 ? 1 : 0;
        }

        // Tracking thread: the pose into the hub; socket thread: the POSE line.
        c0 = countsNow();
        const core::slam::EkfSlam& filter = tracker->filter();
        hub.publishPose(daemon::makePoseReport(filter.pose(), filter.velocityW(),
                                               filter.poseCovariance(), filter.upW(), 1, frame.id,
                                               frame.t_ns));
        const daemon::PoseReport pose = hub.pose();
        pose_line.clear();
        if (pose_limiter.admit(pose.epoch, pose.t_ns)) {
            daemon::appendPose(pose_line, pose, scale_report);
        }
        // Tracking thread: the field log's POSE line (LogEvents::onPose).
        bool log_pose = false;
        if (log_pose_limiter.admit(pose.epoch, pose.t_ns)) {
            daemon::formatEvent(daemon::PoseEvent{.pose = &pose,
                                                  .metric = daemon::metricPose(pose, scale_report),
                                                  .state = scale_report.state},
                                log_line);
            log_pose = true;
        }
        if (counting) {
            pose_stage.add(c0, frame.id);
            ++rec.pose_lines;
            rec.metric_pose_lines += pose_line.find("\"position\":[") != std::string::npos ? 1 : 0;
            if (log_pose) {
                ++rec.pose_log_lines;
                rec.metric_pose_log_lines +=
                    log_line.find("\"position\":[") != std::string::npos ? 1 : 0;
            }
        }

        if (frames_in_map <= 1 || (frames_in_map - 1) % every != 0) {
            continue;
        }
        // Tracking thread: capture, copy the image, swap into the mailbox;
        // detection thread: swap out of it.
        c0 = countsNow();
        const auto cap = staging.capture(tracker->filter(), frame.id, 1);
        frame.color.copyTo(staging_image);
        std::swap(pending, staging);
        std::swap(pending_image, staging_image);
        std::swap(job, pending);
        std::swap(job_image, pending_image);
        if (counting) {
            capture.add(c0, frame.id);
        }
        ASSERT_EQ(cap.status, core::slam::CaptureStatus::kOk) << "frame " << frame.id;

        c0 = countsNow();
        auto det = (*detector)->detect(job_image, job.frameId(), frame.t_ns, boxes);
        if (counting) {
            detect_stage.add(c0, frame.id);
        }
        ASSERT_TRUE(det.ok()) << det.error().message;

        c0 = countsNow();
        const std::size_t n = drivers::detector::toEstimatorDetections(boxes, dets);
        if (counting) {
            convert.add(c0, frame.id);
        }

        c0 = countsNow();
        const core::UpdateStats u =
            estimator->update(job.view(), std::span(dets.data(), n), records);
        const auto log_p = estimator->posterior().logDensity();
        for (std::size_t j = 0; j < log_p.size() && j < log_p_out.size(); ++j) {
            log_p_out[j] = static_cast<double>(log_p[j]);
        }
        const core::ScaleSummary summary = estimator->summary();
        scale_report.has_scale = summary.state != core::ScaleState::kNoData;
        scale_report.scale = static_cast<double>(summary.map);
        scale_report.ci68_lo = static_cast<double>(summary.ci68.lo);
        scale_report.ci68_hi = static_cast<double>(summary.ci68.hi);
        if (counting) {
            update.add(c0, frame.id);
            ++updates;
            observations += u.observations;
        }

        // Detection thread: the table after the update, into the hub and the
        // field log (LogEvents writes the objects this update saw).
        c0 = countsNow();
        daemon::collectObjects(*estimator, summary, objects);
        objects.epoch = 1;
        objects.frame_id = job.frameId();
        hub.publishObjects(objects);
        int lines = 0;
        for (const daemon::ObjectReport& o : objects.objects) {
            if (o.last_frame == objects.frame_id) {
                daemon::formatEvent(
                    daemon::ObjectEvent{
                        .frame_id = objects.frame_id, .t_ns = frame.t_ns, .epoch = 1, .object = &o},
                    log_line);
                ++lines;
            }
        }
        if (counting) {
            table_stage.add(c0, frame.id);
            rec.object_lines += lines;
            rec.max_objects_seen = std::max(rec.max_objects_seen, objects.objects.size());
        }
        // Socket thread: a copy out of the hub, the reply encoded.
        c0 = countsNow();
        hub.objects(socket_copy);
        reply.clear();
        daemon::appendObjects(reply, socket_copy);
        if (counting) {
            reply_stage.add(c0, frame.id);
            rec.objects_reply_bytes = std::max(rec.objects_reply_bytes, reply.size());
        }
    }
    for (const daemon::ObjectReport& o : objects.objects) {
        rec.objects_used += o.state == core::ObjectState::kUsed ? 1 : 0;
    }

    rec.after_summary = estimator->summary();
    const core::ScaleSummary& after_summary = rec.after_summary;
    const auto log_p_after = estimator->posterior().logDensity();
    double& log_p_change = rec.log_p_change;
    for (std::size_t j = 0; j < log_p_after.size() && j < log_p_before.size(); ++j) {
        log_p_change =
            std::max(log_p_change, std::abs(static_cast<double>(log_p_after[j]) - log_p_before[j]));
    }

    rec.table = report(stages);
    const std::string& table = rec.table;
    std::printf(
        "steady state (model %s): %d counted frames after %d warm-up; malloc counted: %s\n"
        "  tracking: %lld matched, %lld inliers (min %d per frame), %d features added on %d "
        "frames, %d new maps\n"
        "  scale: %d updates, %lld observations; MAP %.4f -> %.4f, observations %d -> %d, "
        "max |change| of log p %.3g\n"
        "  objects: up to %zu in the table, %d used at the end, %d OBJECT lines, replies up to "
        "%zu bytes\n  poses: %d POSE lines, %d with a metric part; %d POSE log lines, %d "
        "metric\n%s",
        core::toString(model), counted_frames, kWarmupFrames,
        test::mallocCountingEnabled() ? "yes" : "no (sanitizer)", matched, inliers, min_inliers,
        added, frames_adding, new_maps, updates, observations,
        static_cast<double>(before_summary.map), static_cast<double>(after_summary.map),
        before_summary.observations, after_summary.observations, log_p_change, rec.max_objects_seen,
        rec.objects_used, rec.object_lines, rec.objects_reply_bytes, rec.pose_lines,
        rec.metric_pose_lines, rec.pose_log_lines, rec.metric_pose_log_lines, table.c_str());

    rec.completed = true;
}

class SteadyStateAllocation : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        record_ = std::make_unique<RunRecord>();
        runPipeline(*record_, core::EstimatorModel::kPaper);
    }
    static void TearDownTestSuite() { record_.reset(); }

    void SetUp() override {
        ASSERT_TRUE(record_ != nullptr && record_->completed)
            << "the pipeline run stopped early (see the failure above)";
    }

    static std::unique_ptr<RunRecord> record_;
};

std::unique_ptr<RunRecord> SteadyStateAllocation::record_;

// The work was real: healthy tracking of one map, features matched and
// initialised from corners, estimator updates with observations that moved
// the posterior. Without this a zero count would prove nothing.
TEST_F(SteadyStateAllocation, WorkWasReal) {
    const RunRecord& r = *record_;
    EXPECT_EQ(r.counted_frames, kCountedFrames);
    EXPECT_EQ(r.frames_not_ok, 0);
    EXPECT_EQ(r.new_maps, 0);
    EXPECT_GE(r.min_inliers, 5);
    EXPECT_GT(r.matched, 10LL * kCountedFrames);
    EXPECT_GT(r.added, 0);  // corner detection and new patches in steady state
    EXPECT_GE(r.updates,
              kCountedFrames / daemon::defaultPipelineConfig().detection.every_frames - 1);
    EXPECT_GT(r.observations, 0);
    EXPECT_GT(r.after_summary.observations, r.before_summary.observations);
    EXPECT_NE(r.after_summary.map, r.before_summary.map);
    EXPECT_GT(r.log_p_change, 1e-3);
    // A POSE line per counted frame, in metres once the scale had evidence.
    EXPECT_EQ(r.pose_lines, kCountedFrames);
    EXPECT_GT(r.metric_pose_lines, 0);
    // The field log's at 10 per second of the sim's 30 fps: one in three frames.
    EXPECT_GE(r.pose_log_lines, kCountedFrames / 3 - 1);
    EXPECT_LE(r.pose_log_lines, kCountedFrames / 3 + 2);
    EXPECT_GT(r.metric_pose_log_lines, 0);
}

// The criterion: no operator new in the pipeline's own stages.
TEST_F(SteadyStateAllocation, NoOperatorNew) {
    for (const Stage& st : record_->stages) {
        if (st.asserted) {
            EXPECT_EQ(st.total.news, 0) << st.name << " allocated; per stage:\n" << record_->table;
        }
    }
}

// Nor any malloc (Eigen's dynamic matrices, cv::fastMalloc). See the top of
// the file for why it is disabled.
TEST_F(SteadyStateAllocation, NoMalloc) {
    if (!test::mallocCountingEnabled()) {
        GTEST_SKIP() << "malloc is not counted in this build (sanitizer)";
    }
    for (const Stage& st : record_->stages) {
        if (st.asserted) {
            EXPECT_EQ(st.total.mallocs, 0) << st.name << " called malloc; per stage:\n"
                                           << record_->table;
        }
    }
}

// The same run with estimator.model = "object" (looser anchors, see
// runPipeline), with the object table published after every update.
class SteadyStateAllocationObjects : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        record_ = std::make_unique<RunRecord>();
        runPipeline(*record_, core::EstimatorModel::kObject);
    }
    static void TearDownTestSuite() { record_.reset(); }

    void SetUp() override {
        ASSERT_TRUE(record_ != nullptr && record_->completed)
            << "the pipeline run stopped early (see the failure above)";
    }

    static std::unique_ptr<RunRecord> record_;
};

std::unique_ptr<RunRecord> SteadyStateAllocationObjects::record_;

// Objects were tracked, seen in the counted updates (OBJECT lines) and used
// by the posterior: a zero count is not vacuous.
TEST_F(SteadyStateAllocationObjects, WorkWasReal) {
    const RunRecord& r = *record_;
    EXPECT_EQ(r.counted_frames, kCountedFrames);
    EXPECT_EQ(r.new_maps, 0);
    EXPECT_GE(r.updates,
              kCountedFrames / daemon::defaultPipelineConfig().detection.every_frames - 1);
    EXPECT_GT(r.max_objects_seen, 0U);
    EXPECT_GT(r.object_lines, 0);
    EXPECT_GT(r.objects_used, 0);
    EXPECT_GT(r.objects_reply_bytes, 100U);
}

TEST_F(SteadyStateAllocationObjects, NoOperatorNew) {
    for (const Stage& st : record_->stages) {
        if (st.asserted) {
            EXPECT_EQ(st.total.news, 0) << st.name << " allocated; per stage:\n" << record_->table;
        }
    }
}

TEST_F(SteadyStateAllocationObjects, NoMalloc) {
    if (!test::mallocCountingEnabled()) {
        GTEST_SKIP() << "malloc is not counted in this build (sanitizer)";
    }
    for (const Stage& st : record_->stages) {
        if (st.asserted) {
            EXPECT_EQ(st.total.mallocs, 0) << st.name << " called malloc; per stage:\n"
                                           << record_->table;
        }
    }
}

}  // namespace
}  // namespace scaled
