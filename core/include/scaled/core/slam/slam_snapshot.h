#pragma once

// SlamSnapshot: the SLAM state at the frame a detector ran on.
//
// Detection runs asynchronously: by the time the boxes of frame j come back
// the filter is at frame j + k, has moved the camera and refined (or deleted)
// the features. The boxes must be measured against the geometry of frame j:
// the camera pose, gravity and map points as they were at j. A snapshot is an
// owning copy of exactly that, taken when frame j is handed to the detector,
// and view() gives it to ScaleEstimator::update() together with j's boxes.
//
// Ownership (the threading itself is the daemon's business, core has no
// threads):
//   - the tracking thread owns the filter and calls capture() on a snapshot it
//     owns, right after the frame's update (and manageMap());
//   - it then hands the whole snapshot (with the frame's image) to the
//     detection side, which only reads it (view(), accessors) until it is done;
//   - a snapshot is never read and written at the same time and never shares
//     storage with the filter or with another snapshot. Hand-over by std::swap
//     (or move) exchanges the buffers in O(1) without allocating, so a
//     "latest wins" mailbox is a few snapshots reserved alike and swapped
//     under the daemon's lock. (Copying is allowed but allocates: not for the
//     per-frame path.)
//
// Capacity contract: reserve(max_features) (or create()) allocates once.
// capture() then does not allocate: it clears the buffers and fills at most
// capacity() features. If the filter holds more features (with rho > 0) than
// that, the first capacity() in the filter's order (oldest first) are kept,
// the rest are counted in dropped() and the capture reports kTruncated. The
// snapshot stays usable: it is a subset of the map, with consistent geometry.
// Reserve the filter's SlamConfig::max_features to never truncate.
//
// epoch is a number the caller changes whenever SLAM re-initialises (the map
// and its scale start anew). A consumer compares it with the current epoch and
// drops a detection whose snapshot belongs to an earlier map: its evidence is
// about a scale that no longer exists.

#include <cstdint>
#include <span>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/slam_types.h>
#include <scaled/core/slam/window_ba.h>

namespace scaled::core::slam {

// What a snapshot keeps of a map point besides its geometry (MapFeature).
// Index i describes features()[i], hence ObservationRecord::feature_index.
struct SnapshotFeature {
    std::uint64_t id = 0;
    FeatureKind kind = FeatureKind::kInverseDepth;
    Vec2 px = Vec2::Zero();  // projection by the captured (updated) state
    bool in_view = false;    // px inside the image
    bool measured = false;   // accepted as a match in the captured frame
};

enum class CaptureStatus : std::uint8_t {
    kOk,
    kTruncated,      // more features than capacity(): the first capacity() kept, see dropped()
    kUninitialised,  // the filter has no map yet: pose identity, no features, valid() false
};
const char* toString(CaptureStatus status);

struct CaptureReport {
    CaptureStatus status = CaptureStatus::kOk;
    int captured = 0;  // features in the snapshot
    int dropped = 0;   // features with rho > 0 left out for lack of capacity
};

class SlamSnapshot {
public:
    // Upper bound on reserve(), far above any EKF map (the state is 13 + 6 n).
    static constexpr int kMaxCapacity = 1 << 16;

    // An empty snapshot with capacity 0 (every capture truncates); call reserve().
    SlamSnapshot() = default;
    // A snapshot with reserve(max_features) done.
    static Result<SlamSnapshot> create(int max_features);

    // Sets the capacity and allocates for it (kInvalidArgument outside
    // [0, kMaxCapacity]). Allocates; call it once, not per frame. Clears the
    // snapshot.
    Status reserve(int max_features);

    // Copies the filter's state at its current frame: time, pose and its 6x6
    // covariance, up_W, health, and per map point (as EkfSlam::mapPoints, in
    // the same order; inverse-depth features with rho <= 0 are left out) its
    // id, p_FinW, P_FinW and projection. frame_id is the caller's id of the
    // image (the one the detections will carry), epoch the caller's map epoch.
    // to_served carries all of it (pose, covariance, up_W, points) into the
    // frame and unit of the served pose (MonoTracker::servedFromFilter(): the
    // window bundle adjustment's), so the scale estimator measures the map
    // the served pose is in. Projections are unchanged by a similarity.
    // Does not allocate. On an uninitialised filter the snapshot is emptied
    // (frame_id and epoch are still recorded) and kUninitialised returned.
    CaptureReport capture(const EkfSlam& slam, std::int64_t frame_id, std::uint64_t epoch,
                          const Sim3& to_served = {});

    // Forgets the content (not the capacity).
    void clear();

    // The estimator's view of this snapshot. It points into this object's
    // storage: valid until the next capture(), reserve(), clear(), swap or
    // move of this snapshot.
    [[nodiscard]] FrameSnapshot view() const;

    // Captured from an initialised filter.
    [[nodiscard]] bool valid() const { return valid_; }
    [[nodiscard]] std::int64_t frameId() const { return frame_id_; }
    [[nodiscard]] std::int64_t timestampNs() const { return t_ns_; }
    [[nodiscard]] std::uint64_t epoch() const { return epoch_; }
    [[nodiscard]] std::int64_t slamFrameIndex() const { return slam_frame_; }
    [[nodiscard]] SlamHealth health() const { return health_; }
    [[nodiscard]] const CameraPose& pose() const { return pose_; }
    // Covariance of (position, rotation error), as EkfSlam::poseCovariance().
    [[nodiscard]] const Mat6x6& poseCovariance() const { return pose_cov_; }
    [[nodiscard]] const Vec3& upW() const { return up_W_; }

    [[nodiscard]] std::span<const MapFeature> features() const { return features_; }
    [[nodiscard]] std::span<const SnapshotFeature> featureInfo() const { return info_; }
    [[nodiscard]] int size() const { return static_cast<int>(features_.size()); }
    [[nodiscard]] int capacity() const { return capacity_; }
    // Features left out by the last capture for lack of capacity.
    [[nodiscard]] int dropped() const { return dropped_; }

private:
    void carry(const Sim3& T);

    int capacity_ = 0;
    bool valid_ = false;
    std::int64_t frame_id_ = 0;
    std::int64_t t_ns_ = 0;
    std::uint64_t epoch_ = 0;
    std::int64_t slam_frame_ = 0;
    SlamHealth health_ = SlamHealth::kUninitialised;
    CameraPose pose_;
    Mat6x6 pose_cov_ = Mat6x6::Zero();
    Vec3 up_W_ = Vec3(0, 0, 1);
    int dropped_ = 0;
    std::vector<MapFeature> features_;  // contiguous: view() spans it
    std::vector<SnapshotFeature> info_;
};

}  // namespace scaled::core::slam
