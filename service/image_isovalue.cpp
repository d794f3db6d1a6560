#include "isotouch/service/image_isovalue.h"

#include <sstream>

namespace isotouch::service {

engine::IsoChoice image_isovalue(const engine::Volume& v, const std::optional<core::Isosurface>& client_set) {
  if (client_set && client_set->tau > v.min_value && client_set->tau < v.max_value) {
    engine::IsoChoice c;
    c.iso = *client_set;
    std::ostringstream s;
    s << "a client's isovalue command (kept for each image whose values contain it)";
    c.rule = s.str();
    return c;
  }
  engine::IsoChoice c = engine::choose_isovalue(v, engine::VolumeHints{});
  if (client_set) {
    std::ostringstream s;
    s << "the client's isovalue " << client_set->tau << " lies outside this image's values (" << v.min_value << ", "
      << v.max_value << "), so " << c.rule;
    c.rule = s.str();
  }
  return c;
}

}  // namespace isotouch::service
