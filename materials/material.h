// material.h - what a scene says about the materials in its scan (the scene's "materials"
// section, io/scene.cpp; docs/user-guide.md's field tables). Plain data, no dependencies:
// the scene library (built without Vulkan) fills it, materials/label_volume.h reads the labels.
#pragma once
#include <algorithm>
#include <array>
#include <cctype>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace isotouch::materials {

/// A materials problem. what() names the file, the field (or header key) and the value.
struct MaterialError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// One material: how it feels, how the drill removes it, how it is shown, whether it must
/// not be cut. Units as the scene writes them.
struct Material {
  std::string name;                  ///< not empty, unique in the scene
  /// The label value that marks it in the label map (label maps); for a `.seg.nrrd`, -1 =
  /// take the segment of the same name's SegmentN_LabelValue. Unused by a transfer function.
  int label = -1;
  /// Transfer function: the scan's values [lo, hi) (the volume's units) that are this material.
  double range_lo = 0, range_hi = 0;
  double stiffness_n_per_m = 800;    ///< K [N/m]
  double mu_s = 0, mu_d = 0;         ///< static and dynamic friction coefficients
  double rate = -1;                  ///< drill: value units removed per (N above the threshold) per s; < 0: the brush's
  double density_scale = 0;          ///< drill: density factor [value units]; 0 = the brush's default
  /// Display colour, RGB in [0, 1]; has_color false = the `.seg.nrrd`'s SegmentN_Color, else grey.
  std::array<double, 3> color{0.8, 0.8, 0.8};
  bool has_color = false;
  bool critical = false;             ///< the drill must never remove it
  double margin_mm = 0;              ///< critical: the warning distance from its surface [mm]
};

/// The scene's "materials" section.
struct MaterialsSpec {
  bool present = false;
  /// A label map beside the scan (NIfTI, NRRD, or 3D Slicer's `.seg.nrrd`), resolved
  /// against the scene file's folder; empty = a transfer function on the scan's values.
  std::string labels_path;
  std::vector<Material> list;        ///< in the scene's order; material id = index + 1 (0 = none)
};

/// True for a name ending in `.seg.nrrd` (any case): 3D Slicer's segmentation file, whose
/// materials may be named by segment instead of by label value.
inline bool is_seg_nrrd(const std::string& path) {
  constexpr std::size_t kLen = 9;  // ".seg.nrrd"
  if (path.size() < kLen) return false;
  std::string tail = path.substr(path.size() - kLen);
  std::transform(tail.begin(), tail.end(), tail.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return tail == ".seg.nrrd";
}

}  // namespace isotouch::materials
