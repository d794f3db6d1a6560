// The slice views' planes (apps/sculpt/slices.h) on volumes whose index axes are permuted
// and flipped against the patient axes (a sagittal or coronal acquisition, a RAS header):
// checked through the volume's own physical mapping (engine::Volume::index_to_physical), not
// the slice code's axis choice. tests/cli_slices.py checks the shipped head end to end.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cmath>

#include "isotouch/apps/sculpt/slice_views.h"
#include "isotouch/apps/sculpt/slices.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/materials/label_volume.h"

namespace isotouch::sculpt {
namespace {

using core::Vec3;

/// A 6x5x4 volume whose voxel value is its linear offset, under direction `D` (row-major).
engine::Volume volume_with(const std::array<double, 9>& D) {
  engine::Volume v;
  v.grid.dims = {6, 5, 4};
  v.grid.spacing_m = {1e-3, 2e-3, 3e-3};
  v.direction = D;
  v.direction_is_identity = false;
  v.voxels.resize(v.grid.voxel_count());
  for (std::size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i);
  v.update_stats();
  return v;
}

/// Each plane's screen directions (LPS): right and down; the normal is the third axis.
constexpr std::array<std::array<std::array<int, 2>, 2>, 3> kScreen{{
    {{{0, 1}, {1, 1}}},    // axial: right = left (+x), down = posterior (+y)
    {{{0, 1}, {2, -1}}},   // coronal: right = left, down = inferior (-z)
    {{{1, 1}, {2, -1}}}}};  // sagittal: right = posterior, down = inferior

void expect_planes(const std::array<double, 9>& D, const std::string& what) {
  const engine::Volume v = volume_with(D);
  SliceStyle style;
  style.wl = {0.5 * double(v.voxels.size() - 1), double(v.voxels.size() - 1)};  // grey = value * 255 / (n - 1)
  style.iso = core::Isosurface{1e9, core::InsideIs::kAbove};  // nothing inside: no contour
  style.marks = false;
  for (SliceKind k : kSliceKinds) {
    SCOPED_TRACE(what + ", " + to_string(k));
    const SliceAxes ax = slice_axes(v.direction, k);
    const SliceImage s = make_slice(v.grid, v.voxels, k, ax, Vec3{2, 2, 1}, Vec3{2, 2, 1}, style);
    // Neighbouring pixels' voxels, compared by their physical positions: one column right
    // moves along the plane's right direction, one row down along its down direction, and
    // every pixel lies in one physical plane across the third axis.
    const auto phys = [&](int c, int r) { return slice_pixel_index(s, c, r); };
    const auto [right, down] = kScreen[std::size_t(k)];
    const int normal = 3 - right[0] - down[0];
    const double plane = v.index_to_physical(phys(0, 0))[normal];
    for (int r = 0; r < s.height; ++r)
      for (int c = 0; c < s.width; ++c) {
        const Vec3 p = v.index_to_physical(phys(c, r));
        EXPECT_NEAR(p[normal], plane, 1e-12);
        if (c + 1 < s.width) {
          EXPECT_GT((v.index_to_physical(phys(c + 1, r))[right[0]] - p[right[0]]) * right[1], 0);
        }
        if (r + 1 < s.height) {
          EXPECT_GT((v.index_to_physical(phys(c, r + 1))[down[0]] - p[down[0]]) * down[1], 0);
        }
        // The pixel shows that voxel: its grey is the voxel's value (its offset, every grey
        // distinct) through the window.
        const Vec3 i = phys(c, r);
        const double value = v.voxels[v.grid.index(int(i.x), int(i.y), int(i.z))];
        EXPECT_EQ(s.rgba[std::size_t(r) * std::size_t(s.width) + std::size_t(c)] & 0xFFu, window_grey(value, style.wl));
      }
  }
}

TEST(Slices, PlanesFollowTheDirectionMatrix) {
  expect_planes({1, 0, 0, 0, 1, 0, 0, 0, 1}, "identity (LPS)");
  expect_planes({-1, 0, 0, 0, -1, 0, 0, 0, 1}, "RAS");
  expect_planes({1, 0, 0, 0, 1, 0, 0, 0, -1}, "z inferior (the shipped head)");
  // A sagittal acquisition: index x runs posterior, y inferior, z left.
  expect_planes({0, 0, 1, 1, 0, 0, 0, -1, 0}, "sagittal");
  // A coronal acquisition: index x runs right, y inferior, z anterior.
  expect_planes({-1, 0, 0, 0, 0, -1, 0, -1, 0}, "coronal");
}

TEST(Slices, EdgeLettersSayWhereEachViewPoints) {
  const engine::Volume head = volume_with({1, 0, 0, 0, 1, 0, 0, 0, -1});
  const engine::Volume sag = volume_with({0, 0, 1, 1, 0, 0, 0, -1, 0});
  const auto letters = [](const engine::Volume& v, SliceKind k) {
    const auto e = slice_axes(v.direction, k).edges;
    return std::string(e.begin(), e.end());
  };
  for (const engine::Volume* v : {&head, &sag}) {
    EXPECT_EQ(letters(*v, SliceKind::kAxial), "APRL");  // top, bottom, left, right
    EXPECT_EQ(letters(*v, SliceKind::kCoronal), "SIRL");
    EXPECT_EQ(letters(*v, SliceKind::kSagittal), "SIAP");
  }
}

// A block inside the slice, and one that reaches three of its edges: a voxel on the slice's
// edge is a contour voxel only through a neighbour within the slice.
TEST(Slices, ContourIsTheInsideVoxelsWithAnOutsideNeighbour) {
  struct Block {
    int x0, x1, y0, y1;
  };
  for (const Block& b : {Block{1, 4, 1, 3}, Block{0, 5, 0, 2}}) {
    engine::Volume v = volume_with({1, 0, 0, 0, 1, 0, 0, 0, 1});  // 6 x 5 x 4
    for (float& x : v.voxels) x = 0;
    for (int y = b.y0; y <= b.y1; ++y)
      for (int x = b.x0; x <= b.x1; ++x) v.voxels[v.grid.index(x, y, 2)] = 10;  // in slice z = 2
    SliceStyle style{{5, 10}, core::Isosurface{5, core::InsideIs::kAbove}, false};
    const SliceImage s = make_slice(v.grid, v.voxels, SliceKind::kAxial, slice_axes(v.direction, SliceKind::kAxial),
                                    Vec3{0, 0, 2}, Vec3{0, 0, 2}, style);
    ASSERT_EQ(s.width, 6);
    ASSERT_EQ(s.height, 5);
    const auto in = [&](int c, int r) { return c >= b.x0 && c <= b.x1 && r >= b.y0 && r <= b.y1; };
    const auto out_in_slice = [&](int c, int r) { return c >= 0 && r >= 0 && c < 6 && r < 5 && !in(c, r); };
    for (int r = 0; r < s.height; ++r)
      for (int c = 0; c < s.width; ++c) {
        const bool contour = in(c, r) && (out_in_slice(c - 1, r) || out_in_slice(c + 1, r) ||
                                           out_in_slice(c, r - 1) || out_in_slice(c, r + 1));
        EXPECT_EQ(s.rgba[std::size_t(r * s.width + c)] == kContourRgba, contour) << c << "," << r << " block " << b.x0;
      }
  }
}

// The pane's pixels (resample_into, mapped once per column and row) are the slice pixels
// that pane_to_slice (the mouse's mapping, SliceViews::hit) gives for each pixel centre,
// rounded and clamped, and untouched outside the slice: slices wider, taller and square on
// isotropic and anisotropic spacings, pane sizes even and odd, every slice pixel distinct.
TEST(Slices, PanePixelsAreThePerPixelMapping) {
  for (const auto& [w, h] : {std::array<int, 2>{256, 64}, {64, 256}, {93, 93}, {7, 3}})
    for (const Vec3& sp : {Vec3{1e-3, 1e-3, 1e-3}, Vec3{1.684e-3, 1.684e-3, 5e-3}, Vec3{3.2e-3, 1.5e-3, 3.2e-3}})
      for (int size : {16, 255, 256}) {
        SliceImage s;
        s.width = w;
        s.height = h;
        s.axes.col = 0;
        s.axes.row = 2;
        s.axes.normal = 1;
        s.rgba.resize(std::size_t(w) * std::size_t(h));
        for (std::size_t i = 0; i < s.rgba.size(); ++i) s.rgba[i] = 0x10000000u + std::uint32_t(i);
        const SlicePane made = make_pane(s, sp, size);  // its geometry; the pixels again below
        SlicePane p = made;
        std::fill(p.rgba.begin(), p.rgba.end(), 0xDEADBEEFu);
        resample_into(p, s);
        std::size_t shown = 0;
        for (int y = 0; y < size; ++y)
          for (int x = 0; x < size; ++x) {
            std::uint32_t want = 0xDEADBEEFu;
            if (const auto cr = pane_to_slice(p, s, x + 0.5, y + 0.5)) {
              const int c = std::clamp(int(std::lround((*cr)[0])), 0, w - 1), r = std::clamp(int(std::lround((*cr)[1])), 0, h - 1);
              want = s.rgba[std::size_t(r) * std::size_t(w) + std::size_t(c)];
              ++shown;
            }
            ASSERT_EQ(p.rgba[std::size_t(y) * std::size_t(size) + std::size_t(x)], want)
                << w << "x" << h << " slice, pane " << size << ", pixel " << x << "," << y;
          }
        if (size == 256) {
          EXPECT_GT(shown, std::size_t(size) * std::size_t(size) / 20) << w << "x" << h << " slice, pane " << size;
        }
      }
}

// window_grey against std::lround(255 f), f the value's place in the window clamped to
// [0, 1]: every half-way value (rounded up), its neighbours either side, the ends, values
// past them, NaN (black), on a window where 255 f is the value itself and on an odd one.
TEST(Slices, WindowGreyRoundsAsLround) {
  for (const WindowLevel wl : {WindowLevel{127.5, 255}, WindowLevel{-600, 1500}, WindowLevel{0.3, 0.7}}) {
    const double lo = wl.level - 0.5 * wl.window;
    std::size_t checked = 0;
    for (int k = -3; k <= 258; ++k)
      for (const double x : {double(k), k + 0.5, std::nextafter(k + 0.5, -1e9), std::nextafter(k + 0.5, 1e9), k + 0.25}) {
        const double v = lo + x / 255.0 * wl.window;
        const double f = (v - (wl.level - 0.5 * wl.window)) / wl.window;
        ASSERT_EQ(int(window_grey(v, wl)), int(std::lround(255.0 * std::clamp(f, 0.0, 1.0)))) << "value " << v;
        ++checked;
      }
    EXPECT_EQ(checked, 262u * 5u);
  }
  EXPECT_EQ(window_grey(std::nan(""), WindowLevel{0, 1}), 0);
}

// SliceViews keeps each plane's slice while only the marks move: after every step of a path
// (the HIP and the proxy moving within the planes, across them, an edit that changes the
// voxels, another window/level) its column equals the three panes of the slices made from the
// volume at that step (make_slice with the marks, make_pane).
TEST(Slices, KeptSlicesEqualSlicesMadeAnew) {
  engine::Volume v = volume_with({1, 0, 0, 0, 1, 0, 0, 0, 1});
  const core::Isosurface iso{50, core::InsideIs::kAbove};
  SliceViews kept;
  kept.open(v, iso, false);
  const std::array<int, 2> fb{400, 300};
  struct Step {
    Vec3 hip, proxy;
    long edits;
  };
  const std::vector<Step> path = {{{2, 2, 1}, {2, 2, 1}, 0}, {{3, 2, 1}, {2, 2, 1}, 0}, {{3, 3, 1}, {3, 2, 1}, 0},
                                  {{3, 3, 2}, {3, 3, 1}, 0}, {{3.4, 3, 2}, {3, 3.4, 2}, 0}, {{3, 3, 2}, {3, 3, 2}, 1},
                                  {{4, 1, 2}, {4, 1, 2}, 1}, {{4, 1, 3}, {4, 1, 2}, 2}, {{0, 0, 0}, {5, 4, 3}, 2}};
  std::size_t made = 0;
  for (std::size_t i = 0; i < path.size(); ++i) {
    const Step& st = path[i];
    if (i == 5) v.voxels[v.grid.index(3, 3, 2)] = 1000;  // the edit counted from this step on
    if (i == 7) v.voxels[v.grid.index(4, 1, 3)] = -5;
    if (i == 8) kept.control().wl = {40, 90};
    made += kept.update(v.voxels, st.hip, st.proxy, st.edits, fb);
    // The truth: each plane's slice made from the volume with its marks, and its pane.
    std::vector<std::uint32_t> column;
    for (SliceKind k : kSliceKinds) {
      const SliceImage s = make_slice(v.grid, v.voxels, k, slice_axes(v.direction, k), st.hip, st.proxy,
                                      SliceStyle{kept.control().wl, iso, true});
      const SlicePane p = make_pane(s, v.grid.spacing_m, SliceViews::pane_size(fb));
      column.insert(column.end(), p.rgba.begin(), p.rgba.end());
    }
    ASSERT_EQ(kept.column(), column) << "step " << i;
  }
  EXPECT_EQ(made, path.size()) << "every step changed a mark, the voxels or the window";
}

// A labelled scene's slices (scenes/tooth-labels.json: enamel, dentin, pulp from its NIfTI
// label map) through the pulp's centre, in the three planes: every pixel's colour is judged
// by the label volume as loaded (materials::load_label_volume), not by the drawing code: a
// pixel of a material shows that material's colour from the scene file, blended half over
// its grey inside the material (3D Slicer's fill) and opaque on its boundary (a 4-neighbour
// in the plane of another material, or an isocontour voxel); a pixel of no material is
// grey, or the isocontour's colour. Then a ball "drilled" by the test (set to 0): its
// voxels that were inside show no material.
TEST(SliceLabels, ToothSlicesShowEachMaterialsColourWhereTheLabelVolumeHasIt) {
  const io::Scene scene = io::load_scene(std::string(ISOTOUCH_TEST_DATA) + "/../scenes/tooth-labels.json");
  const engine::Volume vol = io::load_volume(scene.volume_path);
  const materials::LabelVolume lv = materials::load_label_volume(scene.materials, vol);
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  // The colours as the scene file gives them, RGBA8.
  std::vector<std::array<int, 3>> want_rgb(1);
  for (const materials::Material& m : scene.materials.list)
    want_rgb.push_back({int(std::lround(255 * m.color[0])), int(std::lround(255 * m.color[1])), int(std::lround(255 * m.color[2]))});
  SliceLabels labels;
  labels.ids = &lv.ids;
  labels.before = &vol.voxels;
  labels.rgba.assign(1, 0);
  for (const materials::Material& m : lv.materials) labels.rgba.push_back(label_rgba(m.color));
  // The pulp's centre: the mean index of its voxels.
  Vec3 centre{0, 0, 0};
  std::size_t n = 0;
  const auto& d = vol.grid.dims;
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x)
        if (lv.materials[std::max(1, int(lv.at(x, y, z))) - 1].name == "pulp" && lv.at(x, y, z) != 0) {
          centre = centre + Vec3{double(x), double(y), double(z)};
          ++n;
        }
  ASSERT_GT(n, 0u);
  centre = centre * (1.0 / double(n));
  const auto rgb = [](std::uint32_t p) { return std::array<int, 3>{int(p & 0xFF), int(p >> 8 & 0xFF), int(p >> 16 & 0xFF)}; };
  // `cleared`: pixels of a material as loaded that show none after the edit.
  const auto check = [&](const std::vector<float>& shown, const std::vector<std::uint8_t>& truth, const std::string& what,
                         std::size_t& cleared) {
    std::vector<std::size_t> fill(want_rgb.size(), 0), edge(want_rgb.size(), 0);
    cleared = 0;
    for (SliceKind k : kSliceKinds) {
      SCOPED_TRACE(what + ", " + to_string(k));
      SliceStyle style{{1000, 2000}, iso, false, &labels};
      const SliceImage s = make_slice(vol.grid, shown, k, slice_axes(vol.direction, k), centre, centre, style);
      const auto voxel = [&](int c, int r) {
        const Vec3 i = slice_pixel_index(s, c, r);
        return vol.grid.index(int(i.x), int(i.y), int(i.z));
      };
      for (int r = 0; r < s.height; ++r)
        for (int c = 0; c < s.width; ++c) {
          const std::size_t v = voxel(c, r);
          const int id = truth[v];
          const bool in = iso.contains(shown[v]);
          bool other = false, out_nb = false;
          for (const auto& [dc, dr] : {std::array<int, 2>{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
            if (c + dc < 0 || r + dr < 0 || c + dc >= s.width || r + dr >= s.height) continue;
            const std::size_t u = voxel(c + dc, r + dr);
            other = other || truth[u] != id;
            out_nb = out_nb || !iso.contains(shown[u]);
          }
          const std::uint32_t px = s.rgba[std::size_t(r) * std::size_t(s.width) + std::size_t(c)];
          const int g = window_grey(shown[v], style.wl);
          if (id == 0) {
            cleared += lv.ids[v] != 0 ? 1 : 0;
            if (in && out_nb) ASSERT_EQ(px, kContourRgba) << c << "," << r;
            else ASSERT_EQ(rgb(px), (std::array<int, 3>{g, g, g})) << c << "," << r;
            continue;
          }
          const auto& w = want_rgb[std::size_t(id)];
          if (other || (in && out_nb)) {
            ASSERT_EQ(rgb(px), w) << c << "," << r << " boundary of " << lv.materials[std::size_t(id) - 1].name;
            ++edge[std::size_t(id)];
          } else {
            for (int ch = 0; ch < 3; ++ch)  // half and half, rounded
              ASSERT_NEAR(rgb(px)[std::size_t(ch)], 0.5 * (g + w[std::size_t(ch)]), 0.5 + 1e-9)
                  << c << "," << r << " inside " << lv.materials[std::size_t(id) - 1].name << " channel " << ch;
            ++fill[std::size_t(id)];
          }
        }
    }
    for (std::size_t id = 1; id < want_rgb.size(); ++id) {
      EXPECT_GT(fill[id], 0u) << what << ": no filled pixel of " << lv.materials[id - 1].name;
      EXPECT_GT(edge[id], 0u) << what << ": no boundary pixel of " << lv.materials[id - 1].name;
    }
  };
  std::size_t cleared = 1;
  check(vol.voxels, lv.ids, "as loaded", cleared);
  EXPECT_EQ(cleared, 0u);
  // Drilled: a ball of radius 8 voxels around the first inside voxel met going +y from the
  // pulp's centre's column at its height, set to 0 (below the isovalue); its voxels that
  // were inside show no material, those outside from the start (the pulp) keep theirs.
  std::vector<float> drilled = vol.voxels;
  std::vector<std::uint8_t> truth = lv.ids;
  const int cx = int(std::lround(centre.x)), cz = int(std::lround(centre.z));
  int cy = 0;
  while (cy < d[1] && !iso.contains(vol.voxels[vol.grid.index(cx, cy, cz)])) ++cy;
  ASSERT_LT(cy, d[1]);
  std::size_t gone = 0;
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x) {
        if ((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) > 64) continue;
        const std::size_t i = vol.grid.index(x, y, z);
        if (double(vol.voxels[i]) > scene.hri.tau && truth[i] != 0) {  // inside above the isovalue
          truth[i] = 0;
          ++gone;
        }
        drilled[i] = 0;
      }
  ASSERT_GT(gone, 0u);
  check(drilled, truth, "drilled", cleared);
  EXPECT_GT(cleared, 0u) << "the ball is in no slice: the check says little";
}

// The Materials panel's visibility and colours reach the slice views (SliceViews::update
// made again when they change): a hidden material's voxels show no material (grey, or the
// isocontour's colour), a recoloured one its new colour; truth: the label volume.
TEST(SliceLabels, HiddenAndRecolouredMaterialsInTheSliceViews) {
  const io::Scene scene = io::load_scene(std::string(ISOTOUCH_TEST_DATA) + "/../scenes/tooth-labels.json");
  const engine::Volume vol = io::load_volume(scene.volume_path);
  const materials::LabelVolume lv = materials::load_label_volume(scene.materials, vol);
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  SliceViews views;
  views.open(vol, iso, false);
  MaterialsControl mc;
  for (const materials::Material& m : lv.materials)
    mc.rows.push_back({m.name, m.color, true, m.critical, m.margin_mm, m.stiffness_n_per_m, 0});
  views.set_labels(&lv.ids, &vol.voxels, mc);
  const Vec3 centre = vol.grid.to_index(vol.grid.centre_m());
  const std::array<int, 2> fb{640, 480};
  // The axial slice through the centre: its dentin (id 2) pixels off the marks, beside the
  // same slice without labels.
  const auto dentin_pixels = [&](const std::string& tag) {
    EXPECT_TRUE(views.update(vol.voxels, centre, centre, 0, fb)) << tag << ": computed again";
    const SliceImage& shown = views.image(SliceKind::kAxial);
    SliceStyle plain{views.control().wl, iso, false, nullptr};
    const SliceImage grey = make_slice(vol.grid, vol.voxels, SliceKind::kAxial, shown.axes, centre, centre, plain);
    std::vector<std::array<std::uint32_t, 2>> out;  // (the grey slice's pixel, the view's)
    for (int r = 0; r < grey.height; ++r)
      for (int c = 0; c < grey.width; ++c) {
        const Vec3 i = slice_pixel_index(grey, c, r);
        if (lv.at(int(i.x), int(i.y), int(i.z)) != 2 || std::abs(c - shown.hip[0]) <= 2 || std::abs(r - shown.hip[1]) <= 2)
          continue;
        const std::size_t k = std::size_t(r) * std::size_t(grey.width) + std::size_t(c);
        out.push_back({grey.rgba[k], shown.rgba[k]});
      }
    EXPECT_GT(out.size(), 100u) << tag << ": the slice holds dentin";
    return out;
  };
  std::size_t coloured = 0;
  for (const auto& p : dentin_pixels("as the scene says")) coloured += p[1] != p[0];
  EXPECT_GT(coloured, 0u) << "dentin shows its colour";
  views.materials().rows[1].visible = false;
  for (const auto& p : dentin_pixels("dentin hidden")) ASSERT_EQ(p[1], p[0]) << "hidden dentin shows the grey slice's pixel";
  views.materials().rows[1].visible = true;
  views.materials().rows[1].color = {0.0, 0.0, 1.0};  // blue: its boundary pixels are pure blue
  std::size_t blue = 0;
  for (const auto& p : dentin_pixels("dentin blue")) {
    blue += p[1] == 0xFFFF0000u ? 1 : 0;
    ASSERT_GE(int(p[1] >> 16 & 0xFF), int(p[1] & 0xFF)) << "dentin's pixels lean blue";
  }
  EXPECT_GT(blue, 0u) << "dentin's boundary in its new colour";
}

}  // namespace
}  // namespace isotouch::sculpt
