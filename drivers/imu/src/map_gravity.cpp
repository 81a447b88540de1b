#include <cmath>
#include <cstdio>
#include <system_error>

#include <scaled/core/geometry/gravity.h>
#include <scaled/drivers/imu/map_gravity.h>

namespace scaled::drivers::imu {

core::Result<MapGravitySelector> MapGravitySelector::forDataset(const std::filesystem::path& dir) {
    MapGravitySelector s;
    std::error_code ec;
    const auto tum = dir / "accelerometer.txt";
    const auto euroc = dir / "imu0" / "data.csv";
    if (std::filesystem::is_regular_file(tum, ec)) {
        auto log = readTumAccelerometer(tum);
        if (!log) {
            return log.error();
        }
        s.log_ = std::move(*log);
        s.log_path_ = tum;
    } else if (std::filesystem::is_regular_file(euroc, ec)) {
        auto log = readEurocImu(euroc);
        if (!log) {
            return log.error();
        }
        s.log_ = std::move(*log);
        s.log_path_ = euroc;
    }
    return s;
}

namespace {

std::string accelerometerSource(std::string_view label, const core::GravityEstimate& est) {
    char text[192];
    std::snprintf(text, sizeof text, "accelerometer (%.*s, %zu samples, spread %.3f m/s^2)",
                  static_cast<int>(label.size()), label.data(), est.samples,
                  static_cast<double>(est.spread_mps2));
    return text;
}

}  // namespace

MapGravity MapGravitySelector::atMapStart(const source::Frame& frame,
                                          const LiveAccelerometer& live) const {
    core::GravityOptions opt;
    opt.at_t_ns = live.now_ns;
    opt.window_ns = static_cast<int64_t>(std::llround(live.window_s * 1e9));
    const auto est = core::estimateGravityDown(live.samples, live.R_ItoC, opt);
    if (est) {
        MapGravity g;
        g.down_C = est->down_inC;
        g.source = accelerometerSource(live.label, *est);
        return g;
    }
    MapGravity g = atMapStart(frame);
    g.source +=
        "; the accelerometer (" + std::string(live.label) + ") was refused: " + est.error().message;
    return g;
}

MapGravity MapGravitySelector::atMapStart(const source::Frame& frame) const {
    MapGravity g;
    std::string refused;
    if (log_) {
        core::GravityOptions opt;
        opt.at_t_ns = frame.t_ns;
        const auto est = core::estimateGravityDown(log_->samples, log_->R_ItoC, opt);
        if (est) {
            g.down_C = est->down_inC;
            g.source = accelerometerSource(log_path_.filename().string(), *est);
            return g;
        }
        refused = "; the accelerometer was refused: " + est.error().message;
    }
    if (frame.gravity_down_C) {
        g.down_C = *frame.gravity_down_C;
        g.source = "dataset gravity and ground-truth pose" + refused;
    } else {
        g.source = "assumed level camera (down = +y)" + refused;
    }
    return g;
}

}  // namespace scaled::drivers::imu
