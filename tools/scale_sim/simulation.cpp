#include "simulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>

#include <Eigen/Geometry>

#include "stats.h"

namespace scaled::papersim {

using core::BoundingBox;
using core::CameraPose;
using core::MapFeature;
using core::Mat3;
using core::PinholeRadialCamera;
using core::ScaleEstimator;
using core::Vec2;

namespace {

constexpr Scalar kDeg = std::numbers::pi_v<Scalar> / 180;

Mat3 rotX(Scalar a) {
    return Eigen::AngleAxis<Scalar>(a, Vec3::UnitX()).toRotationMatrix();
}
Mat3 rotZ(Scalar a) {
    return Eigen::AngleAxis<Scalar>(a, Vec3::UnitZ()).toRotationMatrix();
}

// Camera pose in the metric world at frame k.
CameraPose worldPose(const TrajectorySpec& t, int k, int frames) {
    const Scalar th =
        2 * std::numbers::pi_v<Scalar> * static_cast<Scalar>(k) / static_cast<Scalar>(frames);
    CameraPose pose;
    pose.p_CinW = t.look_centre_W + Vec3(t.sweep_x_m * std::sin(th),
                                         -t.distance_m + t.sweep_y_m * std::sin(2 * th),
                                         t.sweep_z_m * std::sin(3 * th));
    // Level camera looking along +y: x_C = x_W, y_C = -z_W, z_C = y_W.
    Mat3 R0;
    R0 << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    const Scalar yaw = t.yaw_deg * kDeg * std::sin(th + Scalar(0.5));
    const Scalar pitch = t.pitch_deg * kDeg * std::sin(2 * th + 1);
    const Scalar roll = t.roll_deg * kDeg * std::sin(Scalar(1.5) * th + 2);
    pose.R_CtoW = rotZ(yaw) * R0 * rotX(pitch) * rotZ(roll);
    return pose;
}

struct SimFeature {
    int object = 0;
    Vec3 p_W = Vec3::Zero();
    Vec3 normal_W = Vec3::Zero();
    Vec3 z = Vec3::Zero();  // fixed standard-normal draw: the EKF's correlated error
    int first_seen = -1;
    Mat3 R_ray = Mat3::Identity();  // columns: two perpendiculars, the ray
    Scalar depth0 = 0;
    Vec3 first_camera_W = Vec3::Zero();
    Scalar baseline = 0;  // largest distance from the first camera position so far
};

std::vector<SimFeature> makeFeatures(const ExperimentSpec& spec, std::mt19937& rng) {
    // Drawn in double and rounded to Scalar: a float build of core sees the
    // same scene and noise as a double build (docs/numerics.md compares them).
    std::uniform_real_distribution<double> u01_d(0, 1);
    std::normal_distribution<double> n01_d(0, 1);
    const auto u01 = [&](std::mt19937& g) { return static_cast<Scalar>(u01_d(g)); };
    const auto n01 = [&](std::mt19937& g) { return static_cast<Scalar>(n01_d(g)); };
    std::vector<SimFeature> out;
    for (std::size_t oi = 0; oi < spec.objects.size(); ++oi) {
        const SimObject& o = spec.objects[oi];
        for (int i = 0; i < spec.noise.features_per_object; ++i) {
            SimFeature f;
            f.object = static_cast<int>(oi);
            const Scalar h = o.height_m * (Scalar(0.1) + Scalar(0.8) * u01(rng));
            if (o.shape == Shape::kCylinder) {
                // Texture on the side facing -y (towards the camera), within +-60 deg.
                const Scalar phi = (u01(rng) * 2 - 1) * 60 * kDeg;
                f.normal_W = Vec3(std::sin(phi), -std::cos(phi), 0);
                f.p_W = o.base_W + o.radius_m * f.normal_W + Vec3(0, 0, h);
            } else {
                // Texture on the front face (y = base.y - depth/2).
                const Scalar x = (u01(rng) - Scalar(0.5)) * Scalar(0.9) * o.width_m;
                f.normal_W = Vec3(0, -1, 0);
                f.p_W = o.base_W + Vec3(x, -o.depth_m / 2, h);
            }
            f.z = Vec3(n01(rng), n01(rng), n01(rng));
            out.push_back(f);
        }
    }
    return out;
}

// Silhouette sample points of an object (metric world).
std::vector<Vec3> silhouette(const SimObject& o) {
    std::vector<Vec3> pts;
    if (o.shape == Shape::kCylinder) {
        constexpr int kN = 72;
        for (int i = 0; i < kN; ++i) {
            const Scalar a = 2 * std::numbers::pi_v<Scalar> * static_cast<Scalar>(i) / kN;
            const Vec3 rim(o.radius_m * std::cos(a), o.radius_m * std::sin(a), 0);
            pts.push_back(o.base_W + rim);
            pts.push_back(o.base_W + rim + Vec3(0, 0, o.height_m));
        }
    } else {
        for (const Scalar sx : {Scalar(-0.5), Scalar(0.5)}) {
            for (const Scalar sy : {Scalar(-0.5), Scalar(0.5)}) {
                for (const Scalar sz : {Scalar(0), Scalar(1)}) {
                    pts.push_back(o.base_W + Vec3(sx * o.width_m, sy * o.depth_m, sz * o.height_m));
                }
            }
        }
    }
    return pts;
}

std::optional<BoundingBox> detect(const PinholeRadialCamera& cam, const CameraPose& pose_W,
                                  const std::vector<Vec3>& sil, Scalar sigma_px,
                                  std::mt19937& rng) {
    BoundingBox b{std::numeric_limits<Scalar>::max(), std::numeric_limits<Scalar>::max(),
                  std::numeric_limits<Scalar>::lowest(), std::numeric_limits<Scalar>::lowest()};
    const Mat3 R_WtoC = pose_W.R_CtoW.transpose();
    const auto w = static_cast<Scalar>(cam.width() - 1);
    const auto h = static_cast<Scalar>(cam.height() - 1);
    for (const Vec3& p : sil) {
        const auto px = cam.project(R_WtoC * (p - pose_W.p_CinW));
        if (!px || px->x() < 0 || px->y() < 0 || px->x() > w || px->y() > h) {
            return std::nullopt;  // not wholly in view: a detector would truncate it
        }
        b.x_min_px = std::min(b.x_min_px, px->x());
        b.y_min_px = std::min(b.y_min_px, px->y());
        b.x_max_px = std::max(b.x_max_px, px->x());
        b.y_max_px = std::max(b.y_max_px, px->y());
    }
    std::normal_distribution<double> noise_d(0, static_cast<double>(sigma_px));
    const auto noise = [&](std::mt19937& g) { return static_cast<Scalar>(noise_d(g)); };
    b.x_min_px = std::clamp(b.x_min_px + noise(rng), Scalar(0), w);
    b.y_min_px = std::clamp(b.y_min_px + noise(rng), Scalar(0), h);
    b.x_max_px = std::clamp(b.x_max_px + noise(rng), Scalar(0), w);
    b.y_max_px = std::clamp(b.y_max_px + noise(rng), Scalar(0), h);
    if (!(b.x_max_px > b.x_min_px + 2 && b.y_max_px > b.y_min_px + 2)) {
        return std::nullopt;
    }
    return b;
}

// The SLAM frame: p_S = R0 p_W / d + t0, an arbitrary similarity of the world.
struct SlamFrame {
    Mat3 R0 = Eigen::AngleAxis<Scalar>(Scalar(0.7),
                                       Vec3(Scalar(0.3), Scalar(0.5), Scalar(0.8)).normalized())
                  .toRotationMatrix();
    Vec3 t0 = Vec3(Scalar(0.4), Scalar(-1.2), Scalar(2.0));
    Scalar d = 0;  // metres per SLAM unit

    [[nodiscard]] Vec3 toSlam(const Vec3& p_W) const { return R0 * p_W / d + t0; }
};

// One experiment's frames: the map the estimator sees at each frame, the
// detections every detect_every frames and the estimator's updates.
class ExperimentRun {
public:
    ExperimentRun(const ExperimentSpec& spec, const PinholeRadialCamera& cam,
                  ScaleEstimator& estimator)
        : spec_(spec),
          cam_(cam),
          estimator_(estimator),
          rng_(spec.seed),
          features_(makeFeatures(spec, rng_)) {
        for (const auto& o : spec.objects) {
            silhouettes_.push_back(silhouette(o));
        }
        slam_.d = spec.d_true;
    }

    // Every frame; the updates that added observations go to result.series.
    void run(ExperimentResult& result) {
        for (int k = 0; k < spec_.frames; ++k) {
            const CameraPose pose_W = worldPose(spec_.trajectory, k, spec_.frames);
            mapFeatures(k, pose_W);
            if (k % spec_.detect_every != 0) {
                continue;
            }
            update(k, pose_W, result);
        }
    }

private:
    void mapFeatures(int k, const CameraPose& pose_W);
    void update(int k, const CameraPose& pose_W, ExperimentResult& result);

    const ExperimentSpec& spec_;
    const PinholeRadialCamera& cam_;
    ScaleEstimator& estimator_;
    std::mt19937 rng_;
    std::vector<SimFeature> features_;
    std::vector<std::vector<Vec3>> silhouettes_;
    SlamFrame slam_;
    std::vector<MapFeature> map_;
    std::vector<core::Detection> detections_;
};

// The map at frame k: the visible features with their EKF-like estimates
// and covariances, in the SLAM frame.
void ExperimentRun::mapFeatures(int k, const CameraPose& pose_W) {
    const Mat3& R0 = slam_.R0;
    const Scalar d = slam_.d;
    const Mat3 R_WtoC = pose_W.R_CtoW.transpose();
    const Scalar f = cam_.intrinsics().fx;
    map_.clear();
    for (auto& sf : features_) {
        const Vec3 to_cam = pose_W.p_CinW - sf.p_W;
        const Vec3 p_C = R_WtoC * (sf.p_W - pose_W.p_CinW);
        const auto px = cam_.project(p_C);
        const bool visible = sf.normal_W.dot(to_cam) > 0 && px && px->x() >= 0 && px->y() >= 0 &&
                             px->x() <= Scalar(cam_.width() - 1) &&
                             px->y() <= Scalar(cam_.height() - 1);
        if (!visible) {
            continue;
        }
        if (sf.first_seen < 0) {
            sf.first_seen = k;
            sf.depth0 = to_cam.norm();
            const Vec3 ray = -to_cam.normalized();
            const Vec3 a = ray.unitOrthogonal();
            sf.R_ray.col(0) = a;
            sf.R_ray.col(1) = ray.cross(a);
            sf.R_ray.col(2) = ray;
            sf.first_camera_W = pose_W.p_CinW;
        }
        sf.baseline = std::max(sf.baseline, (pose_W.p_CinW - sf.first_camera_W).norm());
        const Scalar sigma_theta = spec_.noise.pixel_sigma / f;
        const Scalar s_perp = sf.depth0 * sigma_theta;
        const Scalar s0 = sf.depth0 * spec_.noise.depth_rel_sigma0;
        const Scalar tri = sf.baseline / (sf.depth0 * sf.depth0 * sigma_theta);
        const Scalar s_par = 1 / std::sqrt(1 / (s0 * s0) + tri * tri);
        const Vec3 sd(s_perp, s_perp, s_par);
        const Mat3 L = sf.R_ray * sd.asDiagonal();
        const Vec3 p_est_W = sf.p_W + L * sf.z;
        MapFeature mf;
        mf.p_FinW = slam_.toSlam(p_est_W);
        mf.P_FinW = R0 * (L * L.transpose()) * R0.transpose() / (d * d);
        map_.push_back(mf);
    }
}

// The detections at frame k and the estimator's update with them.
void ExperimentRun::update(int k, const CameraPose& pose_W, ExperimentResult& result) {
    const Mat3& R0 = slam_.R0;
    const Scalar d = slam_.d;
    detections_.clear();
    for (std::size_t oi = 0; oi < spec_.objects.size(); ++oi) {
        const auto box = detect(cam_, pose_W, silhouettes_[oi], spec_.noise.box_sigma_px, rng_);
        if (box) {
            detections_.push_back({*box, spec_.objects[oi].class_name, 1});
        }
    }
    core::FrameSnapshot snap;
    snap.pose.R_CtoW = R0 * pose_W.R_CtoW;
    snap.pose.p_CinW = slam_.toSlam(pose_W.p_CinW);
    snap.up_W = R0 * Vec3::UnitZ();
    snap.features = map_;
    const core::UpdateStats stats = estimator_.update(snap, detections_);
    for (std::size_t i = 0; i < stats.rejected.size(); ++i) {
        result.rejected[i] += stats.rejected[i];
    }
    if (stats.observations == 0) {
        return;
    }
    UpdatePoint up;
    up.frame = k;
    up.observations = stats.observations;
    up.summary = estimator_.summary();
    up.rel_error = std::abs(up.summary.map / d - 1);
    result.series.push_back(up);
}

// The update from which the state stays converged, the errors from there
// on against d (metres per SLAM unit), and the final estimate.
void summarise(Scalar d, ExperimentResult& result) {
    std::vector<Scalar> errors;
    result.updates = static_cast<int>(result.series.size());
    for (int u = result.updates - 1; u >= 0; --u) {
        if (result.series[static_cast<std::size_t>(u)].summary.state !=
            core::ScaleState::kConverged) {
            break;
        }
        result.converged_at_update = u;
    }
    if (result.converged_at_update >= 0) {
        int covered = 0;
        for (auto u = static_cast<std::size_t>(result.converged_at_update);
             u < result.series.size(); ++u) {
            const UpdatePoint& up = result.series[u];
            errors.push_back(up.rel_error);
            covered += (up.summary.ci95.lo <= d && d <= up.summary.ci95.hi) ? 1 : 0;
        }
        result.median_rel_error = tools::median(errors);
        Scalar mean = 0;
        for (const Scalar e : errors) {
            mean += e;
        }
        mean /= static_cast<Scalar>(errors.size());
        Scalar var = 0;
        for (const Scalar e : errors) {
            var += (e - mean) * (e - mean);
        }
        result.std_rel_error = std::sqrt(var / static_cast<Scalar>(errors.size()));
        result.ci95_coverage = static_cast<Scalar>(covered) / static_cast<Scalar>(errors.size());
    }
    if (!result.series.empty()) {
        result.final_summary = result.series.back().summary;
        result.final_rel_error = result.series.back().rel_error;
    }
}

}  // namespace

ExperimentResult runExperiment(const ExperimentSpec& spec) {
    ExperimentResult result;
    result.name = spec.name;
    auto cam = PinholeRadialCamera::create(spec.camera);
    if (!cam) {
        result.error = cam.error().message;
        return result;
    }
    auto est = ScaleEstimator::create(spec.estimator, spec.priors, cam.value());
    if (!est) {
        result.error = est.error().message;
        return result;
    }
    ExperimentRun run(spec, cam.value(), est.value());
    run.run(result);
    summarise(spec.d_true, result);
    return result;
}

}  // namespace scaled::papersim
