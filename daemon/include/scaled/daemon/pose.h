#pragma once

// The camera pose of the protocol's POSE (proto_minor 4): the tracker's pose,
// in SLAM units and the first camera's frame, expressed in the epoch's
// gravity-aligned frame G, and its metric part from the latest scale.
//
// G (docs/protocol.md, POSE): origin at the first camera of the epoch; z up
// (against gravity as the map was started with it); x the horizontal
// projection of the first camera's optical axis; y = z cross x (so x forward,
// y left, z up at the start). The tracker's world frame W is the first
// camera's frame (x right, y down, z forward).

#include <array>
#include <cstdint>

#include <Eigen/Core>

#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/types.h>
#include <scaled/daemon/report.h>

namespace scaled::daemon {

// R_WtoG: its rows are G's axes written in W. up_W (gravity's opposite in W)
// need not be normalised; a zero or non-finite up_W counts as -y_W (a level
// first camera). When the optical axis is within 1e-6 rad of vertical, x is
// the horizontal projection of the first camera's -y axis (the image's up)
// instead.
Eigen::Matrix3d gravityAlignedFromMap(const Eigen::Vector3d& up_W);

// The pose report of a tracked frame from the filter's pose (R_CtoW, p_CinW,
// SLAM units), velocity (W, SLAM units/s), 6x6 covariance of (position,
// rotation error delta) with R_true = R_est Exp(delta) (EkfSlam::poseCovariance)
// and up direction (EkfSlam::upW). Fixed-size arithmetic only: no allocation.
PoseReport makePoseReport(const core::CameraPose& pose_W, const core::Vec3& velocity_W,
                          const Eigen::Matrix<core::Scalar, 6, 6>& covariance,
                          const core::Vec3& up_W, std::uint64_t epoch, std::int64_t frame_id,
                          std::int64_t t_ns);

// The metric part of a POSE.
struct MetricPose {
    // A pose exists and the scale report has a scale of the pose's epoch.
    bool has_scale = false;
    double scale = 0;        // d, metres per SLAM unit: the SCALE's MAP
    double scale_sigma = 0;  // sigma_d = (ci68_hi - ci68_lo) / 2
    std::array<double, 3> position_m{0, 0, 0};
    std::array<double, 3> velocity_mps{0, 0, 0};
    // Row-major, G axes: d^2 Sigma_p + sigma_d^2 p p^T (p, Sigma_p in map
    // units; d independent of the map).
    std::array<double, 9> position_cov_m2{};
};

// The pose in metres at the scale of `scale` (all zero, has_scale false, when
// there is none for the pose's epoch, or it is wide_for_poses).
MetricPose metricPose(const PoseReport& pose, const ScaleReport& scale);

// Thins a stream of poses (the socket's POSE lines, socket.pose_rate_hz; the
// field log's, log.pose_rate_hz) to `rate_hz` per second of frame time (the frames'
// t_ns, not the wall clock). Frame time is cut into slots of one period
// centred on the instants origin + k / rate_hz, the origin being the first
// pose's t_ns; the first pose of each slot is admitted, the others in it are
// not. So frames at the rate itself all pass while their timing error
// (against the first pose's) stays below half a period, and over any T seconds of frames at most
// rate_hz * T + 2 poses are admitted. The first pose, the first of a new epoch and one whose t_ns
// went back (a replay restarted) are admitted and set a new origin.
// rate_hz <= 0 admits every pose.
class PoseRateLimiter {
public:
    explicit PoseRateLimiter(double rate_hz);
    bool admit(std::uint64_t epoch, std::int64_t t_ns);

private:
    std::int64_t period_ns_ = 0;
    bool started_ = false;
    std::uint64_t epoch_ = 0;
    std::int64_t origin_ns_ = 0;
    std::int64_t last_t_ns_ = 0;
    std::int64_t last_slot_ = 0;
};

}  // namespace scaled::daemon
