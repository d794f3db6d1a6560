// export.h - what `isotouch export` runs: a volume or a scene's volume to OpenVDB .vdb and its
// isosurface to STL / OBJ / PLY.
#pragma once
#include <optional>
#include <ostream>
#include <string>

#include "isotouch/io/mesh_units.h"

namespace isotouch::run {

struct ExportOptions {
  std::string volume;                 ///< volume file (.vdb, .mhd, .nrrd, .nii ...); or scene
  std::string scene;                  ///< scene JSON: its volume (file or synthetic) and isosurface
  std::string grid;                   ///< .vdb input: the grid to read ("" = first float grid)
  std::optional<double> iso;          ///< --iso: isovalue (value units), overrides scene / .vdb
  std::string inside;                 ///< --inside: "above" / "below" ("" = from scene / .vdb)
  std::string vdb, stl, obj, ply;     ///< outputs ("" = not written)
  std::string volume_out;             ///< --volume: .mha / .nrrd / .nii / .nii.gz through ITK ("" = not written)
  double adaptivity = 0;              ///< volumeToMesh adaptivity in [0, 1]
  io::MeshUnits mesh_units = io::MeshUnits::kMillimetre;  ///< --mesh-units: the meshes' coordinates, mm or m
};

/// Runs the export: loads the volume, resolves the isosurface (--iso/--inside, else the
/// scene's, else the .vdb's suggestion: level set -> tau 0 inside below, or save_vdb's
/// metadata, else the isovalue the volume opens at: engine::choose_isovalue, its rule printed
/// on the isosurface line), writes each requested output atomically (meshes in the physical
/// frame, LPS, in options.mesh_units), prints the mesh figures (triangles, vertices, size [mm],
/// area [m^2], enclosed volume [m^3], closedness) on `out` and progress on `err`.
/// @return 0 on success; 2 on bad usage (no input or both, no output, no isosurface for a
///         mesh with --iso or --inside alone and nothing to complete it, bad --inside); 3 when a mesh was written but is not closed.
/// @throws VdbError / VolumeError / SceneError naming the file and the problem.
int run_export(const ExportOptions& options, std::ostream& out, std::ostream& err);

}  // namespace isotouch::run
