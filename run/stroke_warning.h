// stroke_warning.h - the warning a run gives when its stroke mostly left the surface.
#pragma once
#include <string>

#include "isotouch/run/run_metrics.h"

namespace isotouch::run {

/// A stroke in contact on fewer than this share of its ticks is warned about.
inline constexpr double kStrokeContactWarnBelow = 0.5;

/// "" when the stroke was in contact on at least kStrokeContactWarnBelow of its ticks (or the
/// script has no stroke); else one sentence with the figures (what report.md, summary.json's
/// script.stroke_contact_warning and the run's stderr say). A warning, not a failure: the run
/// measured what it was asked to, and its files say how little of the stroke touched.
std::string stroke_contact_warning(const RunMetrics& m);

}  // namespace isotouch::run
