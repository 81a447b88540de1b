#pragma once

// A point-level simulation of the EKF MonoSLAM loop without images: known 3-D
// points on the walls of a room, a smooth camera path, and a perfect "front
// end" that returns each searched feature's true projection plus Gaussian
// noise (optionally gross outliers). Used for filter behaviour and
// consistency (NEES) tests where image matching must not interfere.

#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/quaternion.h>

namespace scaled::test {

using core::Scalar;
using core::Vec2;
using core::Vec3;

struct PointSimOptions {
    std::uint32_t seed = 1;
    int frames = 300;
    Scalar fps = 30;
    Scalar pixel_noise_px = 0.5;
    Scalar outlier_fraction = 0;  // matches replaced by a wrong pixel 5-15 px away
    // Features are initialised with their true inverse depth and this relative
    // depth std (known scale, for NEES); <= 0 uses the filter's rho0/sigma_rho.
    Scalar known_depth_rel_sigma = 0;
    // A shake on top of the smooth path: yaw and pitch oscillations of this
    // amplitude (rad) at 4 and 5 rad/s (a hand or a drone's vibration that a
    // constant-velocity model cannot follow at a low frame rate).
    Scalar shake_rad = 0;
};

// A filter configuration suited to the point simulation (smooth motion,
// 1 px matches, a map of 60 features).
inline core::slam::SlamConfig pointSimSlamConfig() {
    core::slam::SlamConfig c;
    c.motion = {Scalar(2), Scalar(2)};
    c.pixel_sigma_px = 1;
    c.max_features = 60;
    c.max_measured = 40;
    c.min_visible = 20;
    return c;
}

// Camera-to-world pose of the simulated camera at time t (world z up, camera
// looking roughly along +y, moving along a smooth loop).
inline core::CameraPose pointSimPose(Scalar t, Scalar shake_rad = 0) {
    core::Mat3 R0;  // camera x right = world x, camera y down = -world z, z forward = world y
    R0 << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    const Scalar yaw = Scalar(0.35) * std::sin(Scalar(0.4) * t) + shake_rad * std::sin(4 * t);
    const Scalar pitch =
        Scalar(0.1) * std::sin(Scalar(0.7) * t + 1) + shake_rad * std::sin(5 * t + 2);
    using AA = Eigen::AngleAxis<Scalar>;
    core::CameraPose pose;
    pose.R_CtoW = AA(yaw, Vec3::UnitZ()).toRotationMatrix() * R0 *
                  AA(pitch, Vec3::UnitX()).toRotationMatrix();
    pose.p_CinW =
        Vec3(Scalar(0.6) * std::sin(Scalar(0.5) * t), Scalar(0.3) * std::sin(Scalar(0.3) * t),
             Scalar(1.5) + Scalar(0.1) * std::sin(Scalar(0.9) * t));
    return pose;
}

class PointSlamSim {
public:
    PointSlamSim(const core::PinholeRadialCamera& cam, const PointSimOptions& opt)
        : cam_(cam), opt_(opt), rng_(opt.seed) {
        // Points on three walls and the floor of a room around the path.
        // Drawn in double and rounded: a float build sees the same scene and noise
        // as a double build, so the two differ only by their arithmetic.
        std::uniform_real_distribution<double> u01(-1, 1);
        const auto u = [&](std::mt19937& g) { return static_cast<Scalar>(u01(g)); };
        for (int i = 0; i < 1500; ++i) {
            const int wall = i % 4;
            Vec3 p;
            if (wall == 0) {
                p = Vec3(4 * u(rng_), 4, Scalar(1.5) + Scalar(1.5) * u(rng_));  // far wall
            } else if (wall == 1) {
                p = Vec3(-3, 2 + 2 * u(rng_), Scalar(1.5) + Scalar(1.5) * u(rng_));
            } else if (wall == 2) {
                p = Vec3(3, 2 + 2 * u(rng_), Scalar(1.5) + Scalar(1.5) * u(rng_));
            } else {
                p = Vec3(3 * u(rng_), 2 + 2 * u(rng_), 0);
            }
            points_.push_back(p);
        }
        T0_ = pointSimPose(0, opt.shake_rad);
    }

    // Ground truth in the SLAM world frame (the first camera frame).
    [[nodiscard]] core::CameraPose truthInC0(Scalar t) const {
        const core::CameraPose p = pointSimPose(t, opt_.shake_rad);
        core::CameraPose out;
        out.R_CtoW = T0_.R_CtoW.transpose() * p.R_CtoW;
        out.p_CinW = T0_.R_CtoW.transpose() * (p.p_CinW - T0_.p_CinW);
        return out;
    }
    [[nodiscard]] Vec3 gravityDownC0() const { return T0_.R_CtoW.transpose() * Vec3(0, 0, -1); }
    [[nodiscard]] std::int64_t timeNs(int k) const {
        return static_cast<std::int64_t>(std::llround(Scalar(k) / opt_.fps * Scalar(1e9)));
    }

    // The true mean angular rate of the camera over frame k-1 to k, in the
    // camera frame (what an ideal gyro integrates to).
    [[nodiscard]] Vec3 trueRateC(int k) const {
        const core::Mat3 R0 = pointSimPose(Scalar(k - 1) / opt_.fps, opt_.shake_rad).R_CtoW;
        const core::Mat3 R1 = pointSimPose(Scalar(k) / opt_.fps, opt_.shake_rad).R_CtoW;
        const Eigen::AngleAxis<Scalar> aa(R0.transpose() * R1);
        return aa.axis() * aa.angle() * opt_.fps;
    }

    // Runs one frame k of the loop on the filter (predict must not be called
    // for k = 0), with the gyro's rate for the interval when one is given.
    // Returns the update report.
    core::slam::UpdateReport step(core::slam::EkfSlam& slam, int k,
                                  const core::slam::GyroRate* gyro = nullptr) {
        const Scalar t = Scalar(k) / opt_.fps;
        const core::CameraPose truth = pointSimPose(t, opt_.shake_rad);
        core::slam::UpdateReport report;
        if (k > 0) {
            slam.predict(timeNs(k), gyro);
            const auto preds = slam.predictMeasurements();
            matches_.clear();
            outlier_ids_.clear();
            std::normal_distribution<double> noise_d(0, static_cast<double>(opt_.pixel_noise_px));
            std::uniform_real_distribution<double> unit_d(0, 1);
            const auto noise = [&](std::mt19937& g) { return static_cast<Scalar>(noise_d(g)); };
            const auto unit = [&](std::mt19937& g) { return static_cast<Scalar>(unit_d(g)); };
            for (int i = 0; i < static_cast<int>(preds.size()); ++i) {
                const auto it = point_of_.find(preds[static_cast<size_t>(i)].id);
                if (it == point_of_.end()) {
                    continue;
                }
                const auto z = project(truth, points_[it->second]);
                if (!z) {
                    continue;
                }
                Vec2 zn = *z + Vec2(noise(rng_), noise(rng_));
                if (unit(rng_) < opt_.outlier_fraction) {
                    const Scalar a = 2 * Scalar(M_PI) * unit(rng_);
                    zn = *z + (5 + 10 * unit(rng_)) * Vec2(std::cos(a), std::sin(a));
                    outlier_ids_.push_back(preds[static_cast<size_t>(i)].id);
                }
                matches_.push_back({i, zn});
            }
            report = slam.update(matches_);
            slam.manageMap();
        }
        addFeatures(slam, truth);
        return report;
    }

    [[nodiscard]] const std::vector<std::uint64_t>& outlierIds() const { return outlier_ids_; }
    [[nodiscard]] const Vec3& pointOf(std::uint64_t id) const { return points_[point_of_.at(id)]; }
    [[nodiscard]] Vec3 pointInC0(std::uint64_t id) const {
        return T0_.R_CtoW.transpose() * (pointOf(id) - T0_.p_CinW);
    }

private:
    [[nodiscard]] std::optional<Vec2> project(const core::CameraPose& pose, const Vec3& p) const {
        const Vec3 pc = pose.R_CtoW.transpose() * (p - pose.p_CinW);
        if (pc.z() < Scalar(0.2)) {
            return std::nullopt;
        }
        auto px = cam_.project(pc);
        if (!px || px->x() < 15 || px->y() < 15 || px->x() > Scalar(cam_.width() - 16) ||
            px->y() > Scalar(cam_.height() - 16)) {
            return std::nullopt;
        }
        return px;
    }

    void addFeatures(core::slam::EkfSlam& slam, const core::CameraPose& truth) {
        if (slam.visibleCount() >= slam.config().min_visible && !slam.features().empty()) {
            return;
        }
        const int want = slam.config().min_visible + 5 - slam.visibleCount();
        slam.makeRoom(want);
        int added = 0;
        std::uniform_int_distribution<size_t> pick(0, points_.size() - 1);
        for (int tries = 0; tries < 3000 && added < want; ++tries) {
            const size_t k = pick(rng_);
            const auto px = project(truth, points_[k]);
            if (!px) {
                continue;
            }
            bool free = true;
            for (const auto& f : slam.features()) {
                if (f.in_view && (f.px - *px).norm() < 30) {
                    free = false;
                    break;
                }
            }
            if (!free) {
                continue;
            }
            std::uint64_t id = 0;
            if (opt_.known_depth_rel_sigma > 0) {
                // A depth prior consistent with its own sigma: the true
                // inverse depth perturbed by a draw of that sigma.
                const Scalar rho = 1 / (points_[k] - truth.p_CinW).norm();
                const Scalar sigma = opt_.known_depth_rel_sigma * rho;
                std::normal_distribution<double> draw_d(0, static_cast<double>(sigma));
                const auto draw = [&](std::mt19937& g) { return static_cast<Scalar>(draw_d(g)); };
                id = slam.addFeature(*px, rho + draw(rng_), sigma);
            } else {
                id = slam.addFeature(*px);
            }
            if (id == 0) {
                break;
            }
            point_of_[id] = k;
            ++added;
        }
    }

    core::PinholeRadialCamera cam_;
    PointSimOptions opt_;
    std::mt19937 rng_;
    std::vector<Vec3> points_;
    std::map<std::uint64_t, size_t> point_of_;
    std::vector<core::slam::FeatureMatch> matches_;
    std::vector<std::uint64_t> outlier_ids_;
    core::CameraPose T0_;
};

}  // namespace scaled::test
