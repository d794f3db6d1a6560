// mesh_units.h - the length unit of the coordinates in a mesh file (STL, OBJ, PLY).
// A mesh file has no unit field: slicers for 3D printing, CAD programs and 3D Slicer (which
// reads STL / OBJ / PLY as LPS millimetres since 4.11) take the numbers as millimetres, so
// isotouch writes millimetres unless told otherwise.
#pragma once
#include <optional>
#include <string>

namespace isotouch::io {

enum class MeshUnits {
  kMillimetre,  ///< "mm", the default: what slicers and 3D Slicer read
  kMetre,       ///< "m", isotouch's internal unit
};

/// The numbers written per metre of physical length: 1000 for mm, 1 for m.
inline double units_per_metre(MeshUnits u) { return u == MeshUnits::kMetre ? 1.0 : 1e3; }

/// "mm" or "m".
inline const char* to_string(MeshUnits u) { return u == MeshUnits::kMetre ? "m" : "mm"; }

/// "mm" -> kMillimetre, "m" -> kMetre; anything else (any case, "metres" included) -> nullopt.
inline std::optional<MeshUnits> parse_mesh_units(const std::string& text) {
  if (text == "mm") return MeshUnits::kMillimetre;
  if (text == "m") return MeshUnits::kMetre;
  return std::nullopt;
}

}  // namespace isotouch::io
