// slices.h - the three slice views beside the 3-D view: the axial, coronal and sagittal
// planes of the volume through the probe's position (HIP), shown as radiologists show them
// (3D Slicer's default): axial with anterior up and the patient's left on the right, coronal
// with superior up and the left on the right, sagittal with superior up and anterior on the
// left. Each shows the voxels through a window/level, the isocontour at the session's
// isovalue and the HIP and proxy (VHIP) marks; the patient letters at its edges come from
// the volume's direction matrix. Computed on the CPU from the voxels (the edited ones in the
// app); no Vulkan here.
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "isotouch/core/grid.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sculpt {

enum class SliceKind { kAxial = 0, kCoronal = 1, kSagittal = 2 };
inline constexpr std::array<SliceKind, 3> kSliceKinds{SliceKind::kAxial, SliceKind::kCoronal, SliceKind::kSagittal};
const char* to_string(SliceKind k);  ///< "axial", "coronal", "sagittal"

/// Which index axes a patient plane runs along in a volume: the image's columns go along
/// index axis `col` (decreasing when col_flip), its rows (top to bottom) along `row`, and
/// the plane lies across `normal`.
struct SliceAxes {
  int normal = 2, col = 0, row = 1;
  bool col_flip = false, row_flip = false;
  /// Patient letters (LPS words' initials: A P S I L R) at the image's top, bottom, left and
  /// right edges, from the physical directions the image's axes point to.
  std::array<char, 4> edges{'?', '?', '?', '?'};
};

/// The index axes of plane `k` in a volume whose direction matrix is `direction` (row-major,
/// column a = the physical LPS direction of index axis a): for each of the plane's screen
/// axes (axial: right = left +x, down = posterior +y; coronal: right = left, down = inferior
/// -z; sagittal: right = posterior, down = inferior) the index axis nearest to it in
/// direction, the normal first.
SliceAxes slice_axes(const std::array<double, 9>& direction, SliceKind k);

/// A window/level on the voxels (value units): level - window/2 is black, level + window/2 white.
struct WindowLevel {
  double level = 0, window = 1;
  bool operator==(const WindowLevel&) const = default;
};

/// The CT windows (HU): bone (W 1800, L 400), soft tissue (W 400, L 40), lung (W 1500, L -600).
std::vector<std::pair<std::string, WindowLevel>> ct_windows();

/// The window a volume opens with: CT in HU the CT window the isovalue falls in (bone from
/// 150 HU, lung up to -500 HU, else soft tissue); other data the volume's range [lo, hi].
WindowLevel default_window(double lo, double hi, bool hounsfield, double iso);

/// The grey of `value` through `wl` (0-255).
std::uint8_t window_grey(double value, const WindowLevel& wl);

/// The marks' colours (RGBA8, R in the low byte); no grey (R = G = B) equals any of them.
inline constexpr std::uint32_t kContourRgba = 0xFF2840F0u;  ///< (240, 64, 40)
inline constexpr std::uint32_t kHipRgba = 0xFF1ACCF2u;      ///< (242, 204, 26), the 3-D view's HIP yellow
inline constexpr std::uint32_t kProxyRgba = 0xFF40CC26u;    ///< (38, 204, 64), the 3-D view's VHIP green

/// One slice, one pixel per voxel.
struct SliceImage {
  SliceKind kind = SliceKind::kAxial;
  SliceAxes axes;
  int index = 0;               ///< the slice's voxel plane along axes.normal
  int width = 0, height = 0;   ///< voxels along axes.col and axes.row
  std::vector<std::uint32_t> rgba;
  std::array<int, 2> hip{-1, -1}, proxy{-1, -1};  ///< the marks' pixels (column, row)
};

/// A labelled scene's materials on a slice (materials/label_volume.h): each voxel's material
/// colour blended over its grey, and each material's boundary drawn in its colour.
struct SliceLabels {
  const std::vector<std::uint8_t>* ids = nullptr;  ///< one material id per voxel (0 none); null: no labels
  /// The voxels as loaded: a voxel an edit removed (inside the isosurface here, not in the
  /// voxels shown: materials::edited_id) shows no material. Null: every voxel keeps its id.
  const std::vector<float>* before = nullptr;
  /// Per id (index 0 unused): the material's colour, RGBA8; alpha 0 = hidden (its voxels are
  /// shown as no material's), any other alpha is ignored.
  std::vector<std::uint32_t> rgba;
};

/// The opacity of a material's colour over the grey inside it (3D Slicer's default 2-D fill
/// opacity); its boundary is drawn opaque (Slicer's outline).
inline constexpr double kLabelFillOpacity = 0.5;

/// The colour RGB in [0, 1] as RGBA8 (each channel rounded from 255 x c), opaque.
std::uint32_t label_rgba(const std::array<double, 3>& rgb);

/// A label's fill over a grey (0-255): each channel round((1 - kLabelFillOpacity) x grey +
/// kLabelFillOpacity x the colour's channel), opaque.
std::uint32_t label_fill(std::uint8_t grey, std::uint32_t rgba);

/// What a slice shows besides the voxels.
struct SliceStyle {
  WindowLevel wl;
  core::Isosurface iso;
  bool marks = true;  ///< the HIP and proxy marks
  const SliceLabels* labels = nullptr;  ///< a labelled scene's materials; null: grey only
};

/// The slice of `voxels` (on `grid`: x fastest, then y, then z) along `ax` through the voxel
/// plane nearest `hip_index` (continuous index). Grey: the voxel through the window; with
/// style.labels, a voxel of a material (its id after edits) takes label_fill of its grey, and
/// a material's boundary voxel (one with a 4-neighbour in the plane of another id, or an
/// isocontour voxel) is drawn in the material's colour: the isocontour per material. The
/// isocontour: an inside voxel with a 4-neighbour in the plane outside it (kContourRgba where
/// no material is). The
/// proxy's mark (a green cross) and the HIP's (a yellow cross over it) at their nearest voxels
/// projected onto the plane, arms of 2 voxels.
/// (The same as make_slice without marks, then mark_slice.)
SliceImage make_slice(const core::Grid& grid, const std::vector<float>& voxels, SliceKind k, const SliceAxes& ax,
                      const core::Vec3& hip_index, const core::Vec3& proxy_index, const SliceStyle& style);

/// Sets the marks' pixels of `s` (its axes and size) for the HIP and the proxy (continuous
/// index) and, with `draw`, draws their crosses into it.
void mark_slice(SliceImage& s, const core::Vec3& hip_index, const core::Vec3& proxy_index, bool draw);

/// The continuous voxel index of a slice's pixel (column, row: pixel centres are whole numbers).
core::Vec3 slice_pixel_index(const SliceImage& s, double col, double row);

/// A slice drawn into a square pane: scaled to the physical aspect (nearest voxel), black
/// around it, the patient letters at its edges and its name at the top left.
struct SlicePane {
  int size = 0;
  std::vector<std::uint32_t> rgba;  ///< size x size
  double x0 = 0, y0 = 0;            ///< where the slice's pixel (-0.5, -0.5) corner lies [pane pixels]
  double px_per_col = 1, px_per_row = 1;
};

/// The pane of `s` on a grid of `spacing_m` (its physical aspect), `size` pixels square.
SlicePane make_pane(const SliceImage& s, const core::Vec3& spacing_m, int size);

/// The slice's pixels into `p` (its size, x0, y0 and scale set): pane pixel (x, y) takes the
/// slice pixel nearest to pane_to_slice(x + 0.5, y + 0.5), rounded and clamped into the
/// slice; pixels outside the slice are left as they are. Mapped once per pane column and row
/// (the column depends on x alone, the row on y alone), then a lookup per pixel.
void resample_into(SlicePane& p, const SliceImage& s);

/// The slice pixel (column, row) under pane pixel (x, y); none outside the slice.
std::optional<std::array<double, 2>> pane_to_slice(const SlicePane& p, const SliceImage& s, double x, double y);

}  // namespace isotouch::sculpt
