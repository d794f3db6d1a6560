// export_cmd.cpp - `isotouch export`: options only; the export is run/export.h.
#include "isotouch/apps/export_cmd.h"

#include "isotouch/apps/cli_checks.h"
#include "isotouch/apps/mesh_units_option.h"
#include "isotouch/core/exit_codes.h"

#include <iostream>
#include <memory>

#include "isotouch/run/export.h"

namespace isotouch::app {

Subcommand add_export_command(CLI::App& cli) {
  Subcommand s;
  auto o = std::make_shared<run::ExportOptions>();
  s.app = cli.add_subcommand(
      "export", "Write a volume as OpenVDB .vdb and its isosurface as a closed mesh (binary STL, OBJ, PLY)");
  s.app->footer(
      "Usage: isotouch export (VOLUME | --scene SCENE) [--iso TAU --inside above|below]\n"
      "                  [--vdb OUT.vdb] [--volume OUT.nrrd|.mha|.nii|.nii.gz] [--stl OUT.stl] [--obj OUT.obj]\n"
      "                  [--ply OUT.ply] [--adaptivity A] [--mesh-units mm|m]\n"
      "VOLUME: .mhd/.mha, .nrrd/.nhdr, .nii/.nii.gz, .vdb (a FloatGrid; a level set means tau 0, inside below)\n"
      "or a DICOM series folder (its slices, in HU; with several series, the one with the most slices).\n"
      "The .vdb keeps every voxel exactly (transform = grid frame [m], direction + isosurface as metadata).\n"
      "Meshes (OpenVDB volumeToMesh) are in the physical frame (LPS) in millimetres (--mesh-units m: metres),\n"
      "as the file's header says (SPACE=LPS UNITS=mm), triangles counter-clockwise seen from outside.\n"
      "Every file is written whole or not at all (temp file, fsync, rename); a device, FIFO or '-'\n"
      "(standard output, the figures then go to stderr) is written as a stream; a folder is refused.\n"
      "Exit: 0 done, 1 error (names the file), 2 bad usage, 3 mesh written but not closed.\n"
      "Example: isotouch export data/ct-head-headsq/headsq_64x64x93_int16.mhd --iso 1150 --inside above "
      "--vdb head.vdb --stl head.stl");
  s.app->add_option("volume", o->volume, "Volume file (.mhd .nrrd .nii .vdb ...) or DICOM series folder");
  s.app->add_option("--scene", o->scene, "Scene file: its volume and its isosurface (tau, inside)");
  s.app->add_option("--grid", o->grid, ".vdb input: the grid to read (default: the first float grid)");
  s.app->add_option("--iso", o->iso,
                    "Isovalue tau (value units); overrides the scene's or the .vdb's. Without it (and without one "
                    "in the scene or the .vdb) the volume's own: bone for CT in HU, else the upper three-class Otsu "
                    "threshold (the rule is printed)")
      ->check(finite_number("the isovalue in the volume's units, e.g. --iso 300 for bone in HU"));
  s.app->add_option("--inside", o->inside, "Which side of tau is the object: above (CT density) or below (signed distance)");
  s.app->add_option("--vdb", o->vdb, "Write the volume as OpenVDB .vdb (FloatGrid 'volume')");
  s.app->add_option("--volume", o->volume_out,
                    "Write the volume for 3D Slicer and other tools: .mha (MetaImage), .nrrd, .nii or .nii.gz "
                    "(ITK; float voxels, spacing, origin and direction kept)");
  s.app->add_option("--stl", o->stl, "Write the isosurface as binary STL (3D printing)");
  s.app->add_option("--obj", o->obj, "Write the isosurface as Wavefront OBJ (with vertex normals)");
  s.app->add_option("--ply", o->ply, "Write the isosurface as binary little-endian PLY (with vertex normals)");
  add_mesh_units_option(*s.app, o->mesh_units);
  s.app->add_option("--adaptivity", o->adaptivity, "volumeToMesh adaptivity in [0, 1]: 0 uniform, more = fewer triangles")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  s.run = [o](const std::string&) {
    try {
      return run::run_export(*o, std::cout, std::cerr);
    } catch (const std::exception& e) {
      std::cerr << "isotouch export: error: " << e.what() << "\n";
      return exit_code::kError;
    }
  };
  return s;
}

}  // namespace isotouch::app
