#include <cmath>
#include <optional>
#include <string>

#include <scaled/core/scale/scale_estimator.h>

namespace scaled::core {

const char* toString(EstimatorModel model) {
    switch (model) {
        case EstimatorModel::kPaper:
            return "paper";
        case EstimatorModel::kObject:
            return "object";
    }
    return "unknown";
}

namespace {

// The first parameter outside its EstimatorLimits, named.
std::optional<Error> outOfLimits(const EstimatorConfig& config) {
    using L = EstimatorLimits;
    const auto& lc = config.likelihood;
    const auto& ec = config.extent;
    const LimitCheck checks[] = {
        {"max_features_per_box", static_cast<double>(config.max_features_per_box),
         L::max_features_per_box},
        {"min_detection_score", static_cast<double>(config.min_detection_score),
         L::min_detection_score},
        {"outlier_weight", static_cast<double>(lc.outlier_weight), L::outlier_weight},
        {"outlier_height_range_m", static_cast<double>(lc.outlier_height_range_m),
         L::outlier_height_range_m},
        {"partial_weight", static_cast<double>(lc.partial_weight), L::partial_weight},
        {"min_sigma_m", static_cast<double>(lc.min_sigma_m), L::min_sigma_m},
        {"box_edge_sigma_px", static_cast<double>(ec.box_edge_sigma_px), L::box_edge_sigma_px},
        {"border_margin_px", static_cast<double>(ec.border_margin_px), L::border_margin_px},
        {"min_extent_px", static_cast<double>(ec.min_extent_px), L::min_extent_px},
    };
    if (const LimitCheck* bad = firstOutside(checks)) {
        return makeError(ErrorCode::kInvalidArgument,
                         std::string("scale estimator: ") + bad->name + " must be " +
                             bad->limits.text() + " (got " + formatLimitValue(bad->value) + ")");
    }
    return std::nullopt;
}

}  // namespace

Result<ScaleEstimator> ScaleEstimator::create(const EstimatorConfig& config, PriorTable priors,
                                              const PinholeRadialCamera& camera) {
    if (priors.empty()) {
        return makeError(ErrorCode::kInvalidArgument, "scale estimator: no height priors given");
    }
    if (auto bad = outOfLimits(config)) {
        return *bad;
    }
    const auto& lc = config.likelihood;
    auto posterior = ScalePosterior::create(config.posterior);
    if (!posterior) {
        return posterior.error();
    }
    std::optional<FixedLikelihood> fixed_likelihood;
    if (config.posterior.arithmetic == PosteriorArithmetic::kFixed) {
        auto f = FixedLikelihood::create(posterior->grid(), lc);
        if (!f) {
            return f.error();
        }
        fixed_likelihood.emplace(std::move(f.value()));
    }
    std::optional<ObjectEvidence> objects;
    if (config.model == EstimatorModel::kObject) {
        auto o = ObjectEvidence::create(config.objects, config.extent, lc, priors, camera,
                                        posterior->grid());
        if (!o) {
            return o.error();
        }
        objects.emplace(std::move(o.value()));
    } else if (config.model != EstimatorModel::kPaper) {
        return makeError(ErrorCode::kInvalidArgument, "scale estimator: unknown model");
    }
    return ScaleEstimator(config, std::move(priors), camera, std::move(posterior.value()),
                          std::move(fixed_likelihood), std::move(objects));
}

ScaleEstimator::ScaleEstimator(const EstimatorConfig& config, PriorTable priors,
                               const PinholeRadialCamera& camera, ScalePosterior posterior,
                               std::optional<FixedLikelihood> fixed_likelihood,
                               std::optional<ObjectEvidence> objects)
    : config_(config),
      priors_(std::move(priors)),
      camera_(camera),
      posterior_(std::move(posterior)),
      log_l_(fixed_likelihood ? 0 : posterior_.grid().size(), 0),
      fixed_likelihood_(std::move(fixed_likelihood)),
      fixed_log_l_(fixed_likelihood_ ? posterior_.grid().size() : 0, 0),
      extents_(static_cast<std::size_t>(config.max_features_per_box)),
      extent_features_(static_cast<std::size_t>(config.max_features_per_box), -1),
      objects_(std::move(objects)),
      class_index_(objects_ ? static_cast<std::size_t>(ObjectEvidence::kMaxDetections) : 0, -1) {}

void ScaleEstimator::reset() {
    posterior_.reset();
    if (objects_) {
        objects_->reset();
    }
}

Status ScaleEstimator::setPriors(PriorTable priors) {
    if (objects_) {
        if (auto ok = objects_->setPriors(priors); !ok) {
            return ok;
        }
    }
    priors_ = std::move(priors);
    return {};
}

const HeightPrior* ScaleEstimator::priorFor(const Detection& det) const {
    const HeightPrior* prior = priors_.find(det.class_name);
    if (prior == nullptr || (!prior->upright() && !config_.use_non_upright) ||
        det.score < config_.min_detection_score) {
        return nullptr;
    }
    return prior;
}

UpdateStats ScaleEstimator::updateObjects(const FrameSnapshot& frame,
                                          std::span<const Detection> detections,
                                          std::span<ObservationRecord> records) {
    UpdateStats stats;
    const std::size_t n = std::min(detections.size(), class_index_.size());
    const HeightPrior* first = priors_.priors().data();
    for (std::size_t i = 0; i < n; ++i) {
        const HeightPrior* prior = priorFor(detections[i]);
        class_index_[i] = prior != nullptr ? static_cast<int>(prior - first) : -1;
    }
    stats.detections_skipped = static_cast<int>(detections.size() - n);
    const ObjectEvidence::UpdateStats o =
        objects_->update(frame, detections.first(n), std::span<const int>(class_index_.data(), n),
                         {}, records, &stats.records_written);
    stats.detections_used = o.detections_used;
    stats.detections_skipped += static_cast<int>(n) - o.detections_used;
    stats.observations = o.detections_used;
    stats.objects_used = o.objects_used;
    stats.views_used = o.views_used;
    stats.new_objects = o.new_objects;
    posterior_.reset();
    objects_->addTo(posterior_);
    return stats;
}

bool ScaleEstimator::addObservation(const VerticalExtent& extent, const HeightPrior& prior,
                                    Scalar weight, Scalar* local_estimate) {
    if (fixed_likelihood_) {
        if (!fixed_likelihood_->evaluate(extent, prior, fixed_log_l_) ||
            !posterior_.addFixedLogLikelihood(fixed_log_l_, weight)) {
            return false;
        }
        if (local_estimate != nullptr) {
            *local_estimate = gridModeFixed(posterior_.grid(), fixed_log_l_);
        }
        return true;
    }
    if (!evaluateLogLikelihood(extent, prior, posterior_.grid(), config_.likelihood, log_l_) ||
        !posterior_.addLogLikelihood(log_l_, weight)) {
        return false;
    }
    if (local_estimate != nullptr) {
        *local_estimate = gridMode(posterior_.grid(), log_l_);
    }
    return true;
}

UpdateStats ScaleEstimator::update(const FrameSnapshot& frame,
                                   std::span<const Detection> detections,
                                   std::span<ObservationRecord> records) {
    if (objects_) {
        return updateObjects(frame, detections, records);
    }
    UpdateStats stats;
    for (std::size_t di = 0; di < detections.size(); ++di) {
        const Detection& det = detections[di];
        const HeightPrior* prior = priorFor(det);
        if (prior == nullptr) {
            ++stats.detections_skipped;
            continue;
        }
        // Geometry first, so that per-box weighting knows how many features count.
        std::size_t n = 0;
        for (std::size_t fi = 0; fi < frame.features.size() && n < extents_.size(); ++fi) {
            const ExtentResult r = measureVerticalExtent(
                camera_, frame.pose, frame.up_W, frame.features[fi], det.box, config_.extent);
            if (r.status != ExtentStatus::kOk) {
                // Features outside the box are the common case, not a rejection.
                if (r.status != ExtentStatus::kOutsideBox) {
                    ++stats.rejected[static_cast<std::size_t>(r.status)];
                }
                continue;
            }
            extents_[n] = r.extent;
            extent_features_[n] = static_cast<int>(fi);
            ++n;
        }
        const Scalar weight = config_.weighting == ObservationWeighting::kPerBox && n > 0
                                  ? Scalar(1) / static_cast<Scalar>(n)
                                  : Scalar(1);
        int used = 0;
        for (std::size_t k = 0; k < n; ++k) {
            // The local mode costs a pass over the grid: only for a record.
            Scalar local_estimate = 0;
            const bool record = static_cast<std::size_t>(stats.records_written) < records.size();
            if (!addObservation(extents_[k], *prior, weight, record ? &local_estimate : nullptr)) {
                ++stats.rejected[static_cast<std::size_t>(ExtentStatus::kUnstable)];
                continue;
            }
            ++used;
            ++stats.observations;
            if (static_cast<std::size_t>(stats.records_written) < records.size()) {
                ObservationRecord& rec = records[static_cast<std::size_t>(stats.records_written)];
                rec.detection_index = static_cast<int>(di);
                rec.feature_index = extent_features_[k];
                rec.D = extents_[k].D;
                rec.sigma_D_paper = extents_[k].sigma_D_paper;
                rec.sigma_D_feature = extents_[k].sigma_D_feature;
                rec.sigma_D_box = extents_[k].sigma_D_box;
                rec.local_estimate = local_estimate;
                rec.weight = weight;
                ++stats.records_written;
            }
        }
        if (used > 0) {
            ++stats.detections_used;
        } else {
            ++stats.detections_skipped;
        }
    }
    return stats;
}

}  // namespace scaled::core
