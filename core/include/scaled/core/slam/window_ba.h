#pragma once

// Sliding-window bundle adjustment over the filter's own feature tracks, and
// the scale correction it gives the filter (issue 19, docs/slam.md).
//
// The EKF's map scale wanders by 20-45% over 5 s windows on real sequences:
// each frame's single linearisation passes errors on to the features that
// replace the ones leaving the view. A bundle adjustment of the same matches
// over the last keyframes (every keyframe_every frames, window_keyframes of
// them) re-linearises them all together; the older part of its window
// (fixed_keyframes, already adjusted) holds the gauge, so the newer keyframes
// come out in the unit the older ones had. The ratio of the adjusted unit to
// the filter's scales the filter's motion in the served pose (adjustedPose);
// with scale_feedback it is handed back to the filter instead
// (EkfSlam::rescaleMap), so the map and the scale estimator carry it too.
//
// Keyframe poses are camera-to-world (R_CtoW, p_CinW) in the filter's world
// frame; points are world positions; the residual is the camera model's
// projection minus the measured pixel, Huber-weighted. Levenberg-Marquardt
// with the points eliminated (Schur complement). With a rolling shutter each
// observation is projected through the camera of its row's time. Every buffer
// is sized at create(): adding frames and optimising do not allocate.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Cholesky>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/types.h>

namespace scaled::core::slam {

struct WindowBaConfig {
    bool enabled = true;
    int keyframe_every = 3;     // frames between keyframes
    int window_keyframes = 67;  // keyframes adjusted together (200 frames)
    int fixed_keyframes = 33;   // the window's oldest, held fixed (the gauge)
    int step_keyframes = 12;    // optimise after this many new keyframes
    int max_points = 600;       // distinct features in a window
    int max_observations_per_keyframe = 160;
    int min_views = 3;                       // a point needs this many keyframes
    Scalar min_parallax_rad = Scalar(0.02);  // and this angle between its first and last ray
    Scalar huber_px = 2;
    int iterations = 10;
    // true: the filter's map is rescaled to the adjusted unit after every
    // optimisation (the scale handed back clamped to [1 / (1 + max_scale_step),
    // 1 + max_scale_step]); false: the filter keeps its unit and the served
    // pose scales the filter's motion since the newest keyframe by the ratio
    // of the units.
    bool scale_feedback = false;
    Scalar max_scale_step = Scalar(0.2);
    // 0: addFrame() optimises when one is due. > 0: it only says so
    // (WindowBaReport::due); the caller runs runDue(), possibly on another
    // thread, and takes its result this many frames later (finishDue()), so
    // the frame that starts an optimisation does not wait for it. Less than
    // keyframe_every: no keyframe comes while one runs.
    int defer_frames = 0;
    // Rolling shutter (tracker.rolling_shutter_s): seconds from the first
    // row's exposure to the last's, the frame's timestamp being the first
    // row's; negative when the rows are read from the bottom of the image
    // up (a sensor mounted upside down, its image turned). Each observation is seen from the
    // keyframe's camera at its row's time, moved there by the filter's velocities at the keyframe
    // (the velocity times the unit ratio; neither is adjusted). 0: a global shutter.
    Scalar rolling_shutter_s = 0;
    // > 0 (at least 1e-4): the readout time is estimated in the window as
    // well, one value for the camera shared by every observation, with a
    // prior at rolling_shutter_s of this standard deviation (s, against
    // residuals in pixels), kept within +-rolling_shutter_max_s (0: not
    // estimated); each optimisation starts from the last one's estimate and
    // a new map keeps it. 0: rolling_shutter_s is given.
    Scalar rolling_shutter_sigma_s = 0;
    Scalar rolling_shutter_max_s = Scalar(0.05);
    // > 0 (at least 1e-4): the focal length (fx and fy by one factor) is
    // estimated in the window as well, with a prior at the camera's given
    // one of this relative standard deviation, the factor kept within
    // [1 / (1 + focal_max_rel), 1 + focal_max_rel]; each optimisation
    // starts from the last one's estimate and a new map keeps it. 0: the
    // camera's focal length is given.
    Scalar focal_sigma_rel = 0;
    Scalar focal_max_rel = Scalar(0.3);
    // > 0 (at least 1e-4): the radial distortion's k1 is estimated in the
    // window too, with a prior at the camera's given k1 of this standard
    // deviation, kept within +-k1_max_change of it. 0: given.
    Scalar k1_sigma = 0;
    Scalar k1_max_change = Scalar(0.3);
};

struct WindowBaLimits {
    static constexpr ParamLimits keyframe_every = closed(1, 1000);
    static constexpr ParamLimits window_keyframes = closed(4, 1000);
    static constexpr ParamLimits fixed_keyframes = closed(1, 1000);  // < window_keyframes - 1
    static constexpr ParamLimits step_keyframes = closed(1, 1000);   // <= window - fixed
    static constexpr ParamLimits max_points = closed(1, 100000);
    static constexpr ParamLimits max_observations_per_keyframe = closed(1, 100000);
    static constexpr ParamLimits min_views = closed(2, 1000);
    static constexpr ParamLimits min_parallax_rad = closed(0, 1);
    static constexpr ParamLimits huber_px = openClosed(0, 100);
    static constexpr ParamLimits iterations = closed(1, 100);
    static constexpr ParamLimits max_scale_step = closed(0, 10);
    static constexpr ParamLimits defer_frames = closed(0, 999);  // < keyframe_every
    static constexpr ParamLimits rolling_shutter_s = closed(-1, 1);
    static constexpr ParamLimits rolling_shutter_sigma_s = closed(0, 1);
    static constexpr ParamLimits rolling_shutter_max_s = closed(0, 1);  // >= |rolling_shutter_s|
    static constexpr ParamLimits focal_sigma_rel = closed(0, 1);
    static constexpr ParamLimits focal_max_rel = closed(0, 1);
    static constexpr ParamLimits k1_sigma = closed(0, 1);
    static constexpr ParamLimits k1_max_change = closed(0, 1);
};

Status validate(const WindowBaConfig& config);

// What the window estimates of the camera (the rest is given): a prior's
// width and a bound, both > 0.
[[nodiscard]] inline bool estimatesReadout(const WindowBaConfig& c) {
    return c.rolling_shutter_sigma_s > 0 && c.rolling_shutter_max_s > 0;
}
[[nodiscard]] inline bool estimatesFocal(const WindowBaConfig& c) {
    return c.focal_sigma_rel > 0 && c.focal_max_rel > 0;
}
[[nodiscard]] inline bool estimatesK1(const WindowBaConfig& c) {
    return c.k1_sigma > 0 && c.k1_max_change > 0;
}

// A similarity of the world: p_to = scale R p_from + t.
struct Sim3 {
    Scalar scale = 1;
    Mat3 R = Mat3::Identity();
    Vec3 t = Vec3::Zero();

    [[nodiscard]] bool isIdentity() const {
        return scale == 1 && R == Mat3::Identity() && t == Vec3::Zero();
    }
    [[nodiscard]] Vec3 apply(const Vec3& p_from) const { return scale * (R * p_from) + t; }
    // A camera carried along with the world it is posed in.
    [[nodiscard]] CameraPose apply(const CameraPose& T_CtoW) const {
        return {R * T_CtoW.R_CtoW, apply(T_CtoW.p_CinW)};
    }
    // The covariance of a carried point: its errors turn with the world and
    // grow with its unit (J P J^T, J = scale R).
    [[nodiscard]] Mat3 applyToCovariance(const Mat3& P) const {
        const Mat3 J = scale * R;
        return J * P * J.transpose();
    }
    // The covariance of (position, rotation error in the camera frame) of a
    // carried camera: the position's as a point's, the camera-frame rotation
    // error unchanged.
    [[nodiscard]] Mat6x6 applyToPoseCovariance(const Mat6x6& P) const {
        Mat6x6 out = P;
        out.topLeftCorner<3, 3>() = applyToCovariance(P.topLeftCorner<3, 3>());
        out.topRightCorner<3, 3>() = scale * R * P.topRightCorner<3, 3>();
        out.bottomLeftCorner<3, 3>() = out.topRightCorner<3, 3>().transpose();
        return out;
    }
};

// What one optimisation did.
struct WindowBaReport {
    bool optimised = false;
    int keyframes = 0;  // in the window
    int free_keyframes = 0;
    int points = 0;
    int observations = 0;
    Scalar rms_before_px = 0;
    Scalar rms_after_px = 0;
    // Scale of the adjusted free keyframes against their filter poses
    // (Sim(3) over them and the newest fixed one): > 1, the filter's map had
    // shrunk; 1 when nothing was adjusted. Clamped by max_scale_step.
    Scalar scale = 1;
    // The readout time the window used (estimated with
    // rolling_shutter_sigma_s > 0), seconds.
    Scalar rolling_shutter_s = 0;
    // The focal length the window used over the camera's given one (1 unless
    // estimated with focal_sigma_rel > 0).
    Scalar focal_scale = 1;
    Scalar k1 = 0;  // the radial distortion the window used
    // defer_frames > 0: an optimisation is due; nothing was optimised yet.
    bool due = false;
};

class WindowBa {
public:
    static Result<WindowBa> create(const PinholeRadialCamera& camera, const WindowBaConfig& config);

    // A new map: forget every keyframe (an estimated readout time is kept).
    void reset();

    // After the filter's frame (update, new features): its camera pose and the
    // features it saw. Every keyframe_every-th frame becomes a keyframe; every
    // step_keyframes keyframes the window is optimised and the report says
    // by how much the caller should rescale the filter's map (about the
    // camera's position). Call notifyRescaled() after applying it.
    // v_W (filter units/s, world) and w_C (rad/s, camera frame) are the
    // filter's velocities, used with a rolling shutter.
    WindowBaReport addFrame(const CameraPose& T_CtoW, std::span<const FeatureObservation> obs,
                            const Vec3& v_W = Vec3::Zero(), const Vec3& w_C = Vec3::Zero());

    // With defer_frames > 0, after addFrame() said due: the optimisation
    // itself. Between addFrame() and finishDue() nothing else may touch this
    // object (another thread may be running this).
    WindowBaReport runDue() { return optimise(); }
    // Then, after the frames that passed while it ran (those addFrame() did
    // not see: fewer than keyframe_every, so none is a keyframe), counted
    // into the keyframe schedule.
    void finishDue(int frames_passed) { frames_ += frames_passed; }

    // The filter's map was rescaled by s about centre_W: the stored filter
    // poses follow it.
    void notifyRescaled(Scalar s, const Vec3& centre_W);

    // The adjusted pose of the newest keyframe composed with the filter's
    // motion since it: the camera's pose in the adjusted trajectory.
    [[nodiscard]] CameraPose adjustedPose(const CameraPose& filter_T_CtoW) const;
    // The same as a map of the filter's world to the adjusted one (identity
    // before the first keyframe): adjustedPose(T) is
    // adjustedFromFilter().apply(T), and the map carries the filter's map points,
    // velocity and gravity into the frame and unit of the served pose. (The
    // first window's Sim(3) fit to the filter's positions turns the adjusted
    // world against the filter's, by 45 degrees on redkitchen, where the
    // first window is nearly straight: R is that turn, not only drift.)
    [[nodiscard]] Sim3 adjustedFromFilter() const;
    [[nodiscard]] int keyframeCount() const { return count_; }

private:
    struct Keyframe {
        CameraPose filter;        // the filter's pose when the keyframe was taken
        CameraPose adjusted;      // the window's estimate
        Vec3 v_C = Vec3::Zero();  // the filter's velocity in the camera frame, filter units/s
        Vec3 w_C = Vec3::Zero();  // its angular velocity, rad/s
        int obs_count = 0;
    };
    // The camera of the row a pixel was seen in, relative to the keyframe's:
    // a point at p_C in the keyframe camera is at E (p_C - shift_C) in it.
    struct RowMotion {
        Mat3 E = Mat3::Identity();
        Vec3 shift_C = Vec3::Zero();
    };
    struct Point {
        std::uint64_t id = 0;
        Vec3 p_W = Vec3::Zero();
        int views = 0;     // entries in its views (one per keyframe that saw it)
        int first_kf = 0;  // window index of its first and last view
        int last_kf = 0;
        bool usable = false;
    };
    struct View {
        int kf = 0;  // window index
        int j = 0;   // observation of that keyframe
    };

    WindowBa(const PinholeRadialCamera& camera, const WindowBaConfig& config);

    Keyframe& keyframe(int i);  // window index: 0 = the oldest
    [[nodiscard]] const Keyframe& keyframe(int i) const;
    [[nodiscard]] size_t obsIndex(int i, int j) const;
    [[nodiscard]] std::span<const View> viewsOf(const Point& pt) const;
    void pushKeyframe(const CameraPose& T_CtoW, std::span<const FeatureObservation> obs,
                      const Vec3& v_W, const Vec3& w_C);
    [[nodiscard]] RowMotion rowMotion(const Keyframe& kf, const Vec2& z_px) const;
    WindowBaReport optimise();
    // The first optimisation's result moved into the filter's frame and unit.
    void holdFilterGauge();
    [[nodiscard]] Scalar scaleOfFreeKeyframes(int first_free);
    // The window's points by id, with their views, triangulated from the
    // adjusted poses; usable: enough views, parallax, in front, seen by a free keyframe.
    void gatherPoints(int first_free);
    int findOrAddPoint(std::uint64_t id);
    bool triangulate(Point& pt);
    // Levenberg-Marquardt: one iteration (normal equations, Schur complement,
    // solve, step); false when the cost did not go down (state restored).
    bool iterate(int first_free, Scalar& lambda, Scalar& c);
    [[nodiscard]] Scalar cost() const;
    // The prior terms of cost() of the estimated camera parameters (focal
    // factor, k1, readout time; 0 when all are given).
    [[nodiscard]] Scalar priorCost() const;
    // The camera with the focal length times focal_scale and this k1; false
    // (nothing changed) when the camera cannot be made.
    bool setCameraEstimate(Scalar focal_scale, Scalar k1);
    // The camera's estimated parameters (focal factor, k1, readout time: the
    // readout time's last) in the dense part: their rows, and which are.
    static constexpr int kGlobals = 3;
    void globalRows(int first_free, Eigen::Index (&rows)[kGlobals], bool (&active)[kGlobals]) const;
    void accumulate(int first_free);
    void accumulateView(int i, int j, int first_free);
    void schurComplement(int first_free, Scalar lambda);
    // false: no camera could be made for the step (nothing is to be kept).
    bool step(int first_free);
    // Rows of the dense part: 6 per free keyframe, then the focal factor's,
    // k1's and the readout time's when estimated (the readout time's last).
    [[nodiscard]] Eigen::Index denseDim(int first_free) const;
    [[nodiscard]] int globalCount() const {
        return (estimate_focal_ ? 1 : 0) + (estimate_k1_ ? 1 : 0) + (estimate_readout_ ? 1 : 0);
    }

    PinholeRadialCamera camera_given_;
    PinholeRadialCamera camera_;  // camera_given_ with fx, fy times focal_scale_ and k1_
    WindowBaConfig config_;
    int capacity_ = 0;   // keyframes kept (the window)
    int head_ = 0;       // ring index of the oldest keyframe
    int count_ = 0;      // keyframes in the window
    int frames_ = 0;     // frames since reset
    int since_opt_ = 0;  // keyframes since the last optimisation
    bool first_optimisation_ = true;
    Scalar unit_ratio_ = 1;  // adjusted unit per filter unit (scale_feedback off)
    // The readout time (config_.rolling_shutter_s, or estimated: then the
    // last entry of the dense normal equations, after the free poses').
    Scalar readout_s_ = 0;
    Scalar saved_readout_s_ = 0;
    bool estimate_readout_ = false;
    Scalar focal_scale_ = 1;
    Scalar saved_focal_scale_ = 1;
    Scalar k1_ = 0;
    Scalar saved_k1_ = 0;
    bool estimate_focal_ = false;
    bool estimate_k1_ = false;
    std::vector<Keyframe> keyframes_;
    std::vector<FeatureObservation> obs_;  // capacity_ x max_observations_per_keyframe
    std::vector<int> obs_point_;           // point of each observation, -1: none
    std::vector<Point> points_;
    std::vector<View> views_;  // max_points x capacity_
    int point_count_ = 0;
    int usable_points_ = 0;
    int usable_observations_ = 0;
    // Normal equations: the free poses (6 each) and the estimated focal
    // length and readout time dense, the points 3x3 blocks; per observation
    // of a free keyframe its 6x3 pose-point block, per point its
    // global-point rows (summed over its views).
    MatX H_pp_;
    VecX b_p_;
    MatX S_;
    VecX g_;
    VecX dx_p_;
    std::vector<Mat3> H_ll_;
    std::vector<Vec3> b_l_;
    std::vector<Mat3> H_ll_inv_;
    std::vector<Eigen::Matrix<Scalar, 6, 3>> W_;
    std::vector<Eigen::Matrix<Scalar, 3, kGlobals>> W_g_;  // per point: (focal, k1, readout)
    std::vector<Keyframe> saved_keyframes_;
    std::vector<Point> saved_points_;
    std::vector<Vec3> sim_from_;  // scratch for the Sim(3) fits
    std::vector<Vec3> sim_to_;
};

}  // namespace scaled::core::slam
