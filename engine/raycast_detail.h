// raycast_detail.h - what the ray caster's files (raycast.cpp, raycast_field.cpp,
// raycast_view.cpp) share and nothing else uses.
#pragma once
#include <cstdint>
#include <vector>

#include "isotouch/engine/core_names.h"
#include "isotouch/core/isosurface.h"

namespace isotouch::engine::raycast_detail {

/// (x, y, z) = v as floats (a shared struct's three members).
void set3(float& x, float& y, float& z, const Vec3& v);
/// max |finite value or background|: the scale of cell_distances' margin.
double value_magnitude(const std::vector<float>& values, float background);
/// cell_distances() with the margin's scale `mag` given (a sub-box of a volume uses the
/// whole volume's).
std::vector<std::uint8_t> cell_distances_with(const core::Grid& grid, const std::vector<float>& values,
                                              const core::Isosurface& iso, float background, double mag);

}  // namespace isotouch::engine::raycast_detail
