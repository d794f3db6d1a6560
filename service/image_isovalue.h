// image_isovalue.h - the isovalue a volume received as an IMAGE opens at in `isotouch serve`:
// the one a client set with `isovalue V` while it lies inside the image's values, else the
// one `isotouch run VOLUME` would choose (engine/iso_choice.h: CT in HU -> bone 300 HU, else
// a three-class Otsu). Never the scene's: a scene's isovalue is in its own volume's units
// (the head scene's 1150 scanner units are no isovalue for a CT in HU). Part of isotouch::service.
#pragma once
#include <optional>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/iso_choice.h"
#include "isotouch/engine/volume.h"

namespace isotouch::service {

/// The isovalue (value units of `v`) and inside side the session on `v` runs at, with its
/// rule for the log and the STATUS (engine::iso_line). `client_set`: the isovalue a client
/// set (`isovalue V`), kept when strictly inside (v.min_value, v.max_value)
/// (Volume::update_stats current); otherwise, or without one, engine::choose_isovalue(v)
/// with no hints (an IMAGE carries no modality: HU are recognised by their air, -1024).
engine::IsoChoice image_isovalue(const engine::Volume& v, const std::optional<core::Isosurface>& client_set);

}  // namespace isotouch::service
