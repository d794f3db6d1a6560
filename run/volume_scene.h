// volume_scene.h - `isotouch run VOLUME`: the default touch scene made for a volume file or a
// DICOM folder, instead of a hand-written scene. The isovalue is the one the file chooses
// (engine/iso_choice.h) unless given; the probe approaches along the index axis through the
// volume's centre whose first isosurface crossing is nearest its face of the box (but not on
// it: a crossing on the face is where the scan was cropped), presses along the surface normal
// and strokes on the surface (the touch planned on the true isosurface).
#pragma once
#include <optional>
#include <string>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/iso_choice.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/scene.h"

namespace isotouch::run {

/// Where the probe comes from: along index axis `axis` (0 x, 1 y, 2 z) in direction `sign`
/// (+1: from the low face toward higher indices), the first crossing `air_m` [m] inside the box
/// (grid frame). `found` false: no axis line through the centre meets the surface off the
/// faces (the scene then approaches along -z from above, as scenes/*.json default).
struct Approach {
  int axis = 2, sign = -1;
  double air_m = 0;
  bool found = false;
};

/// Looks along the six index half-axes through the centre voxel: the first voxel inside `iso`
/// counted from each face. A candidate enters the box through background (its face voxel in
/// the three-class Otsu class farthest outside the isosurface: air on a CT; a line entering
/// through tissue enters where the scan was cropped) and has at least 2 voxels outside before
/// the surface. Takes the one with the least room in front (the surface nearest the box,
/// reached first), ties in the order low x face, high x face, low y, high y, low z, high z.
/// When no line enters through background (a smooth field, a signed distance), the same
/// among all lines with 2 voxels outside before the surface.
Approach choose_approach(const engine::Volume& vol, const core::Isosurface& iso);

/// The approach in words: "along +x (index) from the R side (the volume's RAS... letters)".
std::string describe_approach(const engine::Volume& vol, const Approach& a);

/// The default scene for a volume and what was chosen.
struct VolumeScene {
  std::string json;       ///< the scene file's text (what `isotouch run` writes as scene.json)
  io::Scene scene;        ///< parsed from `json` (so the file written is the scene run)
  engine::IsoChoice choice;  ///< the isovalue and its rule (rule "hand (--iso)" when given)
  Approach approach;
  std::string approach_text;
};

/// True for a DICOM folder or a file named as a volume (.mhd .mha .nrrd .nhdr .nii .nii.gz
/// .vdb); false for anything else (a scene is .json).
bool is_volume_path(const std::string& path);

/// The name prefix of a volume made in memory (Python's numpy arrays): "memory:numpy array".
/// Such a name is no file: a scene keeps it as it is (never made absolute against the working
/// folder) and errors name it.
inline constexpr const char* kInMemoryPrefix = "memory:";
/// `name` is an in-memory volume's (kInMemoryPrefix), not a file's.
inline bool is_in_memory_name(const std::string& name) { return name.starts_with(kInMemoryPrefix); }

/// Builds the default scene for `volume_path`: its absolute path, the isovalue (`iso`, inside
/// `inside`, or the file's choice), a script along choose_approach with a stroke along the next
/// index axis (length 40 mm, at most a quarter of the box along it) planned on the true
/// isosurface (script.plan "surface", eval/touch_plan.h), the other fields at their scene
/// defaults. @throws engine::VolumeError (loading) or io::SceneError.
VolumeScene make_volume_scene(const std::string& volume_path, std::optional<double> iso,
                              const std::string& inside = "above");
/// The same for a volume already in memory at the isovalue `choice` (its rule said in the
/// scene's description): `volume_path` is only written into the scene (a recording's scene
/// names it), never read; an in-memory name (is_in_memory_name) is written as it is.
/// `servo_json`: the scene's "servo" section (io::servo_section_json; "": the defaults).
/// @throws io::SceneError.
VolumeScene make_volume_scene(const engine::Volume& volume, const engine::IsoChoice& choice,
                              const std::string& volume_path, const std::string& servo_json = "");

}  // namespace isotouch::run
