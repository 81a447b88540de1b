#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/QR>

#include <scaled/drivers/vision/two_view.h>

namespace scaled::drivers::vision {

namespace {

Eigen::Matrix3d skewOf(const Eigen::Vector3d& v) {
    Eigen::Matrix3d m;
    m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
    return m;
}

// Sampson distances of the pairs under E = [t]x R (x_K = R x_S + t).
void sampson(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
             const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
             Eigen::VectorXd& e) {
    const Eigen::Matrix3d E = skewOf(t) * R;
    for (std::size_t i = 0; i < a.size(); ++i) {
        const Eigen::Vector3d Ea = E * a[i];
        const Eigen::Vector3d Etb = E.transpose() * b[i];
        const double den = Ea.head<2>().squaredNorm() + Etb.head<2>().squaredNorm();
        e(static_cast<Eigen::Index>(i)) = b[i].dot(Ea) / std::sqrt(std::max(den, 1e-30));
    }
}

// Gauss-Newton on the inliers' Sampson distances over the rotation (3) and
// the translation's direction (2): the RANSAC model comes from five points.
void refine(Eigen::Matrix3d& R, Eigen::Vector3d& t, const std::vector<Eigen::Vector3d>& a,
            const std::vector<Eigen::Vector3d>& b) {
    const auto n = static_cast<Eigen::Index>(a.size());
    Eigen::VectorXd e(n);
    Eigen::VectorXd e2(n);
    Eigen::MatrixXd J(n, 5);
    for (int it = 0; it < 10; ++it) {
        sampson(R, t, a, b, e);
        const double cost = e.squaredNorm();
        Eigen::Vector3d u = t.unitOrthogonal();
        const Eigen::Vector3d v = t.cross(u).normalized();
        u = v.cross(t).normalized();
        const auto apply = [&](const Eigen::Matrix<double, 5, 1>& d, Eigen::Matrix3d& Rn,
                               Eigen::Vector3d& tn) {
            Rn = R * Eigen::AngleAxisd(d.head<3>().norm(),
                                       d.head<3>().norm() > 0
                                           ? Eigen::Vector3d(d.head<3>().normalized())
                                           : Eigen::Vector3d::UnitX())
                         .toRotationMatrix();
            tn = (t + d(3) * u + d(4) * v).normalized();
        };
        constexpr double kStep = 1e-6;
        for (int k = 0; k < 5; ++k) {
            Eigen::Matrix<double, 5, 1> d = Eigen::Matrix<double, 5, 1>::Zero();
            d(k) = kStep;
            Eigen::Matrix3d Rn;
            Eigen::Vector3d tn;
            apply(d, Rn, tn);
            sampson(Rn, tn, a, b, e2);
            J.col(k) = (e2 - e) / kStep;
        }
        const Eigen::Matrix<double, 5, 1> step =
            (J.transpose() * J).ldlt().solve(-J.transpose() * e);
        Eigen::Matrix3d Rn;
        Eigen::Vector3d tn;
        apply(step, Rn, tn);
        sampson(Rn, tn, a, b, e2);
        if (!(e2.squaredNorm() < cost)) {
            break;
        }
        R = Rn;
        t = tn;
        if (step.norm() < 1e-10) {
            break;
        }
    }
}

// OpenCV's five-point RANSAC and the cheirality test: x_K = R_StoK x_S + t,
// the inliers of the pose (mask) as unit-plane rays, and their indices.
struct EssentialPose {
    Eigen::Matrix3d R_StoK;
    Eigen::Vector3d t_S_inK;
    std::vector<Eigen::Vector3d> ray_S;
    std::vector<Eigen::Vector3d> ray_K;
    std::vector<std::size_t> index;
};

core::Result<EssentialPose> essentialPose(std::span<const core::Vec2> x_S,
                                          std::span<const core::Vec2> x_K, double threshold) {
    std::vector<cv::Point2d> a;
    std::vector<cv::Point2d> b;
    a.reserve(x_S.size());
    b.reserve(x_K.size());
    for (std::size_t i = 0; i < x_S.size(); ++i) {
        a.emplace_back(static_cast<double>(x_S[i].x()), static_cast<double>(x_S[i].y()));
        b.emplace_back(static_cast<double>(x_K[i].x()), static_cast<double>(x_K[i].y()));
    }
    cv::Mat R;
    cv::Mat t;
    cv::Mat mask;
    try {
        const cv::Mat E = cv::findEssentialMat(a, b, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.999,
                                               threshold, mask);
        if (E.rows != 3 || E.cols != 3) {
            return core::makeError(core::ErrorCode::kDegenerate, "two views: no essential matrix");
        }
        // The pose whose points are in front of both views; mask: its inliers.
        cv::recoverPose(E, a, b, cv::Mat::eye(3, 3, CV_64F), R, t, mask);
    } catch (const cv::Exception& e) {
        return core::makeError(core::ErrorCode::kDegenerate, std::string("two views: ") + e.what());
    }
    EssentialPose p;
    for (int r = 0; r < 3; ++r) {
        p.t_S_inK(r) = t.at<double>(r);
        for (int c = 0; c < 3; ++c) {
            p.R_StoK(r, c) = R.at<double>(r, c);
        }
    }
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (mask.at<unsigned char>(static_cast<int>(i)) != 0) {
            p.ray_S.emplace_back(a[i].x, a[i].y, 1);
            p.ray_K.emplace_back(b[i].x, b[i].y, 1);
            p.index.push_back(i);
        }
    }
    return p;
}

}  // namespace

core::Result<TwoViewMotion> estimateTwoViewMotion(std::span<const core::Vec2> x_S,
                                                  std::span<const core::Vec2> x_K, double focal_px,
                                                  double threshold_px, std::span<double> depth_K) {
    constexpr std::size_t kMinPairs = 8;
    if (x_S.size() != x_K.size() || (!depth_K.empty() && depth_K.size() != x_K.size())) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "two views: " + std::to_string(x_S.size()) + " and " +
                                   std::to_string(x_K.size()) + " points differ in number");
    }
    if (x_S.size() < kMinPairs || !(focal_px > 0) || !(threshold_px > 0)) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "two views: " + std::to_string(x_S.size()) +
                                   " pairs (at least 8), focal " + std::to_string(focal_px) +
                                   " px, threshold " + std::to_string(threshold_px) + " px");
    }
    auto pose = essentialPose(x_S, x_K, threshold_px / focal_px);
    if (!pose) {
        return pose.error();
    }
    EssentialPose& p = *pose;
    if (p.ray_S.size() >= 6) {
        refine(p.R_StoK, p.t_S_inK, p.ray_S, p.ray_K);
    }
    // K's attitude in S is R_StoK^T, its centre -R_StoK^T t.
    TwoViewMotion m;
    m.inliers = static_cast<int>(p.ray_S.size());
    m.R_KtoS = p.R_StoK.transpose().cast<core::Scalar>();
    m.t_KinS = (-p.R_StoK.transpose() * p.t_S_inK).cast<core::Scalar>();
    std::fill(depth_K.begin(), depth_K.end(), 0.0);
    std::vector<double> parallax;
    parallax.reserve(p.ray_S.size());
    for (std::size_t j = 0; j < p.ray_S.size(); ++j) {
        const Eigen::Vector3d turned_S = p.R_StoK * p.ray_S[j];
        parallax.push_back(
            std::acos(std::clamp(turned_S.normalized().dot(p.ray_K[j].normalized()), -1.0, 1.0)) *
            180.0 / std::numbers::pi);
        // Depths along both rays: z_S (R a) + t = z_K b, least squares.
        Eigen::Matrix<double, 3, 2> A;
        A.col(0) = turned_S;
        A.col(1) = -p.ray_K[j];
        const Eigen::Vector2d z = A.colPivHouseholderQr().solve(-p.t_S_inK);
        if (!depth_K.empty() && z(0) > 0 && z(1) > 0 && z(1) < 50) {
            depth_K[p.index[j]] = z(1) * p.ray_K[j].norm();  // along the ray, not its z
        }
    }
    if (!parallax.empty()) {
        const auto mid = parallax.begin() + static_cast<std::ptrdiff_t>(parallax.size() / 2);
        std::nth_element(parallax.begin(), mid, parallax.end());
        m.median_parallax_deg = *mid;
    }
    return m;
}

}  // namespace scaled::drivers::vision
