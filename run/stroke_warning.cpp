#include "isotouch/run/stroke_warning.h"

#include "isotouch/run/text.h"

namespace isotouch::run {

std::string stroke_contact_warning(const RunMetrics& m) {
  if (m.stroke_ticks == 0) return "";
  const double share = double(m.stroke_contact_ticks) / double(m.stroke_ticks);
  if (share >= kStrokeContactWarnBelow) return "";
  return "the stroke was in contact on " + std::to_string(m.stroke_contact_ticks) + " of its " +
         std::to_string(m.stroke_ticks) + " ticks (" + fmt(100.0 * share, 3) + " %, under " +
         fmt(100.0 * kStrokeContactWarnBelow, 3) + " %): the probe slid off the surface or the renderer let go, so "
         "the contact figures describe little of the stroke (hand path: script.plan \"" + m.plan +
         "\"; trace.csv shows where contact ended)";
}

}  // namespace isotouch::run
