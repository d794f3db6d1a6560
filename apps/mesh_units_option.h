// mesh_units_option.h - `--mesh-units mm|m`, shared by every command that writes a mesh
// (isotouch export, isotouch run's drilled.stl, isotouch-sculpt's Ctrl+E).
#pragma once
#include <string>

#include <CLI/CLI.hpp>

#include "isotouch/io/mesh_units.h"

namespace isotouch::app {

/// Adds `--mesh-units mm|m` to `app`, parsed into `units` (default millimetres). Any other
/// value is a usage error: "--mesh-units: must be mm or m, got cm".
inline CLI::Option* add_mesh_units_option(CLI::App& app, io::MeshUnits& units) {
  const CLI::Validator mm_or_m(
      [](std::string& s) -> std::string { return io::parse_mesh_units(s) ? "" : "must be mm or m, got " + s; },
      "mm|m");
  return app
      .add_option_function<std::string>(
          "--mesh-units", [&units](const std::string& s) { units = *io::parse_mesh_units(s); },
          "Unit of the coordinates in mesh files (STL, OBJ, PLY; physical frame, LPS): mm (default, what 3D Slicer "
          "and 3D-printing slicers read) or m")
      ->check(mm_or_m)
      ->default_str("mm");
}

}  // namespace isotouch::app
