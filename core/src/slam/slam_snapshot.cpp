#include <string>

#include <scaled/core/slam/slam_snapshot.h>

namespace scaled::core::slam {

const char* toString(CaptureStatus status) {
    switch (status) {
        case CaptureStatus::kOk:
            return "ok";
        case CaptureStatus::kTruncated:
            return "truncated";
        case CaptureStatus::kUninitialised:
            return "uninitialised";
    }
    return "unknown";
}

Result<SlamSnapshot> SlamSnapshot::create(int max_features) {
    SlamSnapshot s;
    const auto r = s.reserve(max_features);
    if (!r.ok()) {
        return r.error();
    }
    return s;
}

Status SlamSnapshot::reserve(int max_features) {
    if (max_features < 0 || max_features > kMaxCapacity) {
        return makeError(ErrorCode::kInvalidArgument,
                         "SlamSnapshot: max_features = " + std::to_string(max_features) +
                             " outside [0, " + std::to_string(kMaxCapacity) + "]");
    }
    clear();
    capacity_ = max_features;
    const auto n = static_cast<std::size_t>(max_features);
    features_.reserve(n);
    info_.reserve(n);
    return {};
}

void SlamSnapshot::clear() {
    valid_ = false;
    frame_id_ = 0;
    t_ns_ = 0;
    epoch_ = 0;
    slam_frame_ = 0;
    health_ = SlamHealth::kUninitialised;
    pose_ = CameraPose{};
    pose_cov_.setZero();
    up_W_ = Vec3(0, 0, 1);
    dropped_ = 0;
    features_.clear();
    info_.clear();
}

CaptureReport SlamSnapshot::capture(const EkfSlam& slam, std::int64_t frame_id, std::uint64_t epoch,
                                    const Sim3& to_served) {
    clear();
    frame_id_ = frame_id;
    epoch_ = epoch;
    t_ns_ = slam.timestampNs();
    slam_frame_ = slam.frameIndex();
    health_ = slam.health();
    up_W_ = slam.upW();
    CaptureReport report;
    if (health_ == SlamHealth::kUninitialised) {
        report.status = CaptureStatus::kUninitialised;
        return report;
    }
    valid_ = true;
    pose_ = slam.pose();
    pose_cov_ = slam.poseCovariance();

    MapPoint point;
    for (int slot = 0; slot < static_cast<int>(slam.features().size()); ++slot) {
        if (!slam.mapPoint(slot, point)) {
            continue;  // at or beyond infinity: no finite point (as mapPoints)
        }
        if (size() == capacity_) {
            ++dropped_;
            continue;
        }
        features_.push_back({point.p_FinW, point.P_FinW});
        info_.push_back({point.id, point.kind, point.px, point.in_view, point.measured});
    }
    if (!to_served.isIdentity()) {
        carry(to_served);
    }
    report.captured = size();
    report.dropped = dropped_;
    report.status = dropped_ > 0 ? CaptureStatus::kTruncated : CaptureStatus::kOk;
    return report;
}

void SlamSnapshot::carry(const Sim3& T) {
    pose_ = T.apply(pose_);
    up_W_ = T.R * up_W_;
    pose_cov_ = T.applyToPoseCovariance(pose_cov_);
    for (MapFeature& f : features_) {
        f.p_FinW = T.apply(f.p_FinW);
        f.P_FinW = T.applyToCovariance(f.P_FinW);
    }
}

FrameSnapshot SlamSnapshot::view() const {
    FrameSnapshot s;
    s.frame_id = frame_id_;
    s.pose = pose_;
    s.up_W = up_W_;
    s.features = features_;
    return s;
}

}  // namespace scaled::core::slam
