// slice_views.h - the sculpting window's three slice views (slices.h): a column of three
// square panes (axial, coronal, sagittal from the top) at the window's right edge, over the
// 3-D picture, each through the HIP. They are computed again only when the HIP or the proxy
// moves to another voxel, the volume is edited, the window/level or the window's size
// changes (at most once a frame); a plane whose voxels did not change (only its marks moved)
// is marked again, not read from the volume again. The window copies the column over its
// picture (Window::set_inset); screenshots get the same column. With the mouse probe, a press
// on a pane moves the probe's target to the voxel under it (in that pane's plane).
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "isotouch/apps/sculpt/slices.h"
#include "isotouch/engine/volume.h"

namespace isotouch::sculpt {

/// The slice views' window/level in the tool panel (value units), and the CT windows.
struct SliceControl {
  WindowLevel wl;
  double lo = 0, hi = 1;  ///< the volume's range: the sliders' ends
  std::vector<std::pair<std::string, WindowLevel>> presets;
  bool shown = false;     ///< the slice views are on (the panel shows their controls)
};

/// Draws the window/level sliders and the CT window buttons into the current ImGui window
/// (a build with Dear ImGui; a no-op otherwise).
void slice_widgets(SliceControl& c);

/// One material of a labelled scene in the Materials panel: what the slice views show of it
/// (visible, colour: the user changes them) and what the scene says of it (shown only).
struct MaterialRow {
  std::string name;
  std::array<double, 3> color{0.8, 0.8, 0.8};    ///< RGB in [0, 1] (the scene's until the user picks another)
  bool visible = true;                           ///< false: the slice views show its voxels as no material's
  bool critical = false;                         ///< the drill never removes it
  double margin_mm = 0;                          ///< critical: its warning distance
  double stiffness_n_per_m = 0;                  ///< K
  long voxels = 0;                               ///< its voxels as loaded
  bool operator==(const MaterialRow&) const = default;
};

/// The Materials panel: one row per material, id = index + 1; empty without materials.
struct MaterialsControl {
  std::vector<MaterialRow> rows;
  bool operator==(const MaterialsControl&) const = default;
};

/// Draws the materials section into the current ImGui window (the tool panel) when there are
/// materials: per material a visibility checkbox and a colour editor (the slice views follow
/// them), its name, K, critical and margin, its voxels as loaded (a build with Dear ImGui; a
/// no-op otherwise).
void material_widgets(MaterialsControl& c);

/// The slice colours of `c`: per id its colour RGBA8 (label_rgba), alpha 0 when hidden.
std::vector<std::uint32_t> material_rgba(const MaterialsControl& c);

class SliceViews {
 public:
  /// The planes of `vol` (its direction matrix), the isocontour at `iso`, the default window.
  void open(const engine::Volume& vol, const core::Isosurface& iso, bool hounsfield);
  /// A labelled scene's materials: `ids` (one per voxel) and `before` (the voxels as loaded,
  /// slices.h SliceLabels) must outlive the views; `materials` the Materials panel's rows,
  /// whose colours and visibility the views follow (materials()). Shown from the next update on.
  void set_labels(const std::vector<std::uint8_t>* ids, const std::vector<float>* before, MaterialsControl materials);
  MaterialsControl& materials() { return materials_; }
  SliceControl& control() { return control_; }
  const SliceControl& control() const { return control_; }
  /// The panes' size for a framebuffer of `fb` pixels: a third of its height, at most a quarter of its width.
  static int pane_size(const std::array<int, 2>& fb);
  /// Computes the slices and panes again when something they show changed (the HIP's or the
  /// proxy's voxel [continuous index], `edits` (a count of applied edits), the window/level,
  /// the framebuffer's size). True when they were computed.
  bool update(const std::vector<float>& voxels, const core::Vec3& hip_index, const core::Vec3& proxy_index, long edits,
              const std::array<int, 2>& fb);
  /// The column of panes (pane_size wide, three high), RGBA; empty before the first update.
  const std::vector<std::uint32_t>& column() const { return column_; }
  int size() const { return size_; }
  /// The column's left edge in the framebuffer [pixels].
  int column_x() const { return fb_[0] - size_; }
  /// Plane `k`'s slice as last computed (one pixel per voxel, marks drawn).
  const SliceImage& image(SliceKind k) const { return images_[std::size_t(k)]; }
  /// The index axis across plane `k`.
  int normal_axis(SliceKind k) const { return axes_[std::size_t(k)].normal; }
  /// Framebuffer pixel (x, y) is on the column of panes.
  bool over(double x, double y) const {
    return !column_.empty() && x >= column_x() && x < fb_[0] && y >= 0 && y < 3 * size_;
  }
  /// The voxel (continuous index) under framebuffer pixel (x, y), and the pane's plane; none off the panes.
  std::optional<std::pair<SliceKind, core::Vec3>> hit(double x, double y) const;
  /// Copies the column into `picture` (w x h RGBA, the window's framebuffer size).
  void compose(std::vector<std::uint32_t>& picture, int w, int h) const;
  /// Writes DIR/axial.png, coronal.png, sagittal.png (one pixel per voxel) and DIR/slices.json
  /// (each slice's axes, plane, marks' pixels and pane geometry, the window/level, the isovalue,
  /// and `hip_phys_mm`, the HIP in the volume's physical frame). @throws std::runtime_error.
  void dump(const std::string& dir, const core::Vec3& hip_phys_mm) const;

 private:
  core::Grid grid_;
  core::Isosurface iso_;
  SliceControl control_;
  SliceLabels labels_;
  MaterialsControl materials_;
  std::array<SliceAxes, 3> axes_{};
  std::array<SliceImage, 3> images_{};
  std::array<SlicePane, 3> panes_{};
  std::vector<std::uint32_t> column_;
  int size_ = 0;
  std::array<int, 2> fb_{0, 0};
  // What the last update showed.
  struct Key {
    std::array<long, 6> voxels{};
    long edits = -1;
    WindowLevel wl;
    std::array<int, 2> fb{0, 0};
    std::vector<std::uint32_t> colours;  // the materials' (material_rgba)
    bool operator==(const Key&) const = default;
  };
  std::optional<Key> shown_;
  // Each plane's slice without marks and what it was made from (its voxel plane, the edits,
  // the window/level): when only the marks moved, it is marked again, not made again.
  struct PlainKey {
    int index = -1;
    long edits = -1;
    WindowLevel wl;
    std::vector<std::uint32_t> colours;
    bool operator==(const PlainKey&) const = default;
  };
  std::array<SliceImage, 3> plain_{};
  std::array<std::optional<PlainKey>, 3> plain_key_{};
};

}  // namespace isotouch::sculpt
