#include "isotouch/apps/sculpt/slices.h"

#include <algorithm>
#include <cmath>

#include "isotouch/materials/label_export.h"

namespace isotouch::sculpt {

using core::Vec3;

namespace {

/// A physical screen axis: LPS axis (0 x, 1 y, 2 z) and sign.
struct PhysAxis {
  int axis;
  int sign;
};

/// The plane's physical normal, right and down axes (LPS).
std::array<PhysAxis, 3> plane_axes(SliceKind k) {
  switch (k) {
    case SliceKind::kAxial: return {{{2, 1}, {0, 1}, {1, 1}}};      // right = left, down = posterior
    case SliceKind::kCoronal: return {{{1, 1}, {0, 1}, {2, -1}}};   // right = left, down = inferior
    case SliceKind::kSagittal: return {{{0, 1}, {1, 1}, {2, -1}}};  // right = posterior, down = inferior
  }
  return {};
}

/// The patient letter of a physical LPS direction: its largest component's.
char patient_letter(const Vec3& d) {
  int a = 0;
  for (int i = 1; i < 3; ++i)
    if (std::abs(d[i]) > std::abs(d[a])) a = i;
  static constexpr char kPos[3] = {'L', 'P', 'S'}, kNeg[3] = {'R', 'A', 'I'};
  return d[a] >= 0 ? kPos[a] : kNeg[a];
}

Vec3 column(const std::array<double, 9>& D, int a) { return {D[std::size_t(a)], D[std::size_t(3 + a)], D[std::size_t(6 + a)]}; }

/// The unused index axis whose physical direction has the largest |component| along `p`.
int nearest_axis(const std::array<double, 9>& D, PhysAxis p, const std::array<bool, 3>& used) {
  int best = -1;
  for (int a = 0; a < 3; ++a)
    if (!used[std::size_t(a)] && (best < 0 || std::abs(D[std::size_t(3 * p.axis + a)]) > std::abs(D[std::size_t(3 * p.axis + best)])))
      best = a;
  return best;
}

int dim(const core::Grid& g, int a) { return g.dims[std::size_t(a)]; }

/// A 5x7 bitmap (rows top to bottom, bit 4 the leftmost column) of the letters the panes write.
const std::array<std::uint8_t, 7>* glyph(char c) {
  static const std::pair<char, std::array<std::uint8_t, 7>> kGlyphs[] = {
      {'A', {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}}, {'C', {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}},
      {'G', {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}}, {'I', {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}},
      {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}}, {'O', {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}},
      {'P', {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}}, {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}},
      {'S', {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}}, {'X', {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}},
      {'?', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04}}};
  for (const auto& [ch, bits] : kGlyphs)
    if (ch == c) return &bits;
  return nullptr;
}

/// Writes `text` into a pane at (x, y) (its top left), `scale` pixels per font pixel, white on
/// a dark outline so that it reads over any grey.
void draw_text(SlicePane& p, const std::string& text, int x, int y, int scale) {
  const auto put = [&](int px, int py, std::uint32_t c) {
    if (px >= 0 && py >= 0 && px < p.size && py < p.size) p.rgba[std::size_t(py) * std::size_t(p.size) + std::size_t(px)] = c;
  };
  for (int pass = 0; pass < 2; ++pass)
    for (std::size_t i = 0; i < text.size(); ++i) {
      const auto* g = glyph(text[i]);
      if (!g) continue;
      for (int r = 0; r < 7; ++r)
        for (int c = 0; c < 5; ++c) {
          if (!((*g)[std::size_t(r)] >> (4 - c) & 1)) continue;
          const int gx = x + (int(i) * 6 + c) * scale, gy = y + r * scale;
          for (int dy = -1; dy <= scale; ++dy)
            for (int dx = -1; dx <= scale; ++dx) {
              const bool body = dx >= 0 && dy >= 0 && dx < scale && dy < scale;
              if (pass == 0 && !body) put(gx + dx, gy + dy, 0xFF000000u);  // the outline first
              if (pass == 1 && body) put(gx + dx, gy + dy, 0xFFFFFFFFu);
            }
        }
    }
}

int text_width(const std::string& t, int scale) { return (int(t.size()) * 6 - 1) * scale; }

/// A cross of arms 2 pixels at (c, r), clipped to the image.
void draw_cross(SliceImage& s, std::array<int, 2> at, std::uint32_t rgba) {
  for (int d = -2; d <= 2; ++d) {
    for (const auto& [c, r] : {std::array<int, 2>{at[0] + d, at[1]}, std::array<int, 2>{at[0], at[1] + d}})
      if (c >= 0 && r >= 0 && c < s.width && r < s.height) s.rgba[std::size_t(r) * std::size_t(s.width) + std::size_t(c)] = rgba;
  }
}

}  // namespace

const char* to_string(SliceKind k) {
  switch (k) {
    case SliceKind::kAxial: return "axial";
    case SliceKind::kCoronal: return "coronal";
    case SliceKind::kSagittal: return "sagittal";
  }
  return "?";
}

SliceAxes slice_axes(const std::array<double, 9>& D, SliceKind k) {
  const std::array<PhysAxis, 3> p = plane_axes(k);
  std::array<bool, 3> used{false, false, false};
  SliceAxes ax;
  int* const which[3] = {&ax.normal, &ax.col, &ax.row};
  for (std::size_t i = 0; i < 3; ++i) {
    *which[i] = nearest_axis(D, p[i], used);
    used[std::size_t(*which[i])] = true;
  }
  ax.col_flip = D[std::size_t(3 * p[1].axis + ax.col)] * p[1].sign < 0;
  ax.row_flip = D[std::size_t(3 * p[2].axis + ax.row)] * p[2].sign < 0;
  const Vec3 right = column(D, ax.col) * (ax.col_flip ? -1.0 : 1.0);
  const Vec3 down = column(D, ax.row) * (ax.row_flip ? -1.0 : 1.0);
  ax.edges = {patient_letter(-down), patient_letter(down), patient_letter(-right), patient_letter(right)};
  return ax;
}

std::vector<std::pair<std::string, WindowLevel>> ct_windows() {
  return {{"bone", {400, 1800}}, {"soft tissue", {40, 400}}, {"lung", {-600, 1500}}};
}

WindowLevel default_window(double lo, double hi, bool hounsfield, double iso) {
  if (hounsfield) {
    const auto w = ct_windows();
    return iso >= 150 ? w[0].second : iso <= -500 ? w[2].second : w[1].second;
  }
  return {0.5 * (lo + hi), hi > lo ? hi - lo : 1.0};
}

std::uint32_t label_rgba(const std::array<double, 3>& rgb) {
  std::uint32_t out = 0xFF000000u;
  for (int k = 0; k < 3; ++k)
    out |= std::uint32_t(std::lround(255.0 * std::clamp(rgb[std::size_t(k)], 0.0, 1.0))) << (8 * k);
  return out;
}

std::uint32_t label_fill(std::uint8_t grey, std::uint32_t rgba) {
  std::uint32_t out = 0xFF000000u;
  for (int k = 0; k < 3; ++k) {
    const double c = double(rgba >> (8 * k) & 0xFFu);
    out |= std::uint32_t(std::lround((1.0 - kLabelFillOpacity) * grey + kLabelFillOpacity * c)) << (8 * k);
  }
  return out;
}

std::uint8_t window_grey(double value, const WindowLevel& wl) {
  const bool nan = !(value == value);  // NaN: black
  const double f = ((nan ? 0.0 : value) - (wl.level - 0.5 * wl.window)) / wl.window;
  // std::lround of x in [0, 255] (halves away from zero) without the library call: truncation
  // is floor there and x minus it exact. Selects, not branches (make_slice calls this per
  // voxel, of unpredictable greys; std::floor is a branchy sequence without SSE4.1): 4x faster
  // on an axial slice of the chest.
  const double x = 255.0 * std::clamp(f, 0.0, 1.0);
  const int t = int(x);
  const int g = t + (x - double(t) >= 0.5 ? 1 : 0);
  return nan ? std::uint8_t(0) : std::uint8_t(g);
}

SliceImage make_slice(const core::Grid& grid, const std::vector<float>& voxels, SliceKind k, const SliceAxes& ax,
                      const Vec3& hip_index, const Vec3& proxy_index, const SliceStyle& style) {
  SliceImage s;
  s.kind = k;
  s.axes = ax;
  s.width = dim(grid, ax.col);
  s.height = dim(grid, ax.row);
  s.index = std::clamp(int(std::lround(hip_index[ax.normal])), 0, dim(grid, ax.normal) - 1);
  s.rgba.assign(std::size_t(s.width) * std::size_t(s.height), 0xFF000000u);
  // The voxel under pixel (c, r): the slice's offset plus a column's and a row's (x fastest,
  // flips applied), and whether it is inside the object.
  const std::array<std::size_t, 3> stride{1, std::size_t(grid.dims[0]), std::size_t(grid.dims[0]) * std::size_t(grid.dims[1])};
  const std::size_t base = std::size_t(s.index) * stride[std::size_t(ax.normal)];
  std::vector<std::size_t> col_at(std::size_t(s.width));
  for (int c = 0; c < s.width; ++c)
    col_at[std::size_t(c)] = std::size_t(ax.col_flip ? s.width - 1 - c : c) * stride[std::size_t(ax.col)];
  // Inside or not per voxel, with a border of inside around the slice (a voxel on the slice's
  // edge is a contour voxel only by a neighbour within it). No branch per voxel: the greys and
  // the inside test are selects.
  const std::size_t W = std::size_t(s.width) + 2;
  std::vector<std::uint8_t> inside(W * (std::size_t(s.height) + 2), 1);
  for (int r = 0; r < s.height; ++r) {
    const std::size_t row_at = base + std::size_t(ax.row_flip ? s.height - 1 - r : r) * stride[std::size_t(ax.row)];
    std::uint32_t* out = s.rgba.data() + std::size_t(r) * std::size_t(s.width);
    std::uint8_t* in = inside.data() + (std::size_t(r) + 1) * W + 1;
    for (int c = 0; c < s.width; ++c) {
      const double v = double(voxels[row_at + col_at[std::size_t(c)]]);
      in[c] = style.iso.contains(v) ? 1 : 0;
      const std::uint32_t g = window_grey(v, style.wl);
      out[c] = 0xFF000000u | g << 16 | g << 8 | g;
    }
  }
  // A labelled scene: each pixel's material after edits (0 none), the same border trick
  // (the border repeats no id: a pixel on the slice's edge is a boundary only by a
  // neighbour within the slice).
  const SliceLabels* lab = style.labels && style.labels->ids ? style.labels : nullptr;
  constexpr std::uint16_t kBorder = 0xFFFF;
  std::vector<std::uint16_t> id;
  if (lab) {
    id.assign(inside.size(), kBorder);
    for (int r = 0; r < s.height; ++r) {
      const std::size_t row_at = base + std::size_t(ax.row_flip ? s.height - 1 - r : r) * stride[std::size_t(ax.row)];
      std::uint32_t* out = s.rgba.data() + std::size_t(r) * std::size_t(s.width);
      std::uint16_t* at = id.data() + (std::size_t(r) + 1) * W + 1;
      for (int c = 0; c < s.width; ++c) {
        const std::size_t v = row_at + col_at[std::size_t(c)];
        std::uint8_t m = (*lab->ids)[v];
        if (lab->before) m = materials::edited_id(m, (*lab->before)[v], voxels[v], style.iso);
        if (m >= lab->rgba.size() || (lab->rgba[m] >> 24) == 0) m = 0;  // no colour, or hidden: no material
        at[c] = m;
        if (m) out[c] = label_fill(std::uint8_t(out[c] & 0xFFu), lab->rgba[m]);
      }
    }
  }
  for (int r = 0; r < s.height; ++r) {
    std::uint32_t* out = s.rgba.data() + std::size_t(r) * std::size_t(s.width);
    const std::uint8_t* in = inside.data() + (std::size_t(r) + 1) * W + 1;
    if (!lab) {
      for (int c = 0; c < s.width; ++c) {
        const bool edge = in[c] & ~(in[c - 1] & in[c + 1] & in[std::ptrdiff_t(c) - std::ptrdiff_t(W)] & in[c + W]);
        out[c] = edge ? kContourRgba : out[c];
      }
      continue;
    }
    // The isocontour per material: an isocontour voxel, or one with a 4-neighbour of another
    // id, in its material's colour (the isocontour where no material is).
    const std::uint16_t* at = id.data() + (std::size_t(r) + 1) * W + 1;
    for (int c = 0; c < s.width; ++c) {
      const bool iso_edge = in[c] & ~(in[c - 1] & in[c + 1] & in[std::ptrdiff_t(c) - std::ptrdiff_t(W)] & in[c + W]);
      const std::uint16_t m = at[c];
      const auto other = [m](std::uint16_t n) { return n != m && n != kBorder; };
      const bool label_edge = m != 0 && (other(at[c - 1]) || other(at[c + 1]) ||
                                         other(at[std::ptrdiff_t(c) - std::ptrdiff_t(W)]) || other(at[c + W]));
      if (m != 0 && (iso_edge || label_edge)) out[c] = lab->rgba[m] | 0xFF000000u;
      else if (iso_edge) out[c] = kContourRgba;
    }
  }
  mark_slice(s, hip_index, proxy_index, style.marks);
  return s;
}

void mark_slice(SliceImage& s, const Vec3& hip_index, const Vec3& proxy_index, bool draw) {
  // The marks: the index projected onto the plane, in pixels.
  const SliceAxes& ax = s.axes;
  const auto pixel = [&](const Vec3& idx) {
    const int ic = int(std::lround(idx[ax.col])), ir = int(std::lround(idx[ax.row]));
    return std::array<int, 2>{ax.col_flip ? s.width - 1 - ic : ic, ax.row_flip ? s.height - 1 - ir : ir};
  };
  s.hip = pixel(hip_index);
  s.proxy = pixel(proxy_index);
  if (draw) {
    draw_cross(s, s.proxy, kProxyRgba);
    draw_cross(s, s.hip, kHipRgba);
  }
}

Vec3 slice_pixel_index(const SliceImage& s, double col, double row) {
  double i[3];
  i[s.axes.col] = s.axes.col_flip ? s.width - 1 - col : col;
  i[s.axes.row] = s.axes.row_flip ? s.height - 1 - row : row;
  i[s.axes.normal] = s.index;
  return {i[0], i[1], i[2]};
}

void resample_into(SlicePane& p, const SliceImage& s) {
  const int size = p.size;
  // pane_to_slice's column depends on x alone and its row on y alone: both mapped once per
  // pane column and row (-1: outside the slice), then every pixel is a lookup.
  std::vector<int> col(std::size_t(size), -1), row(std::size_t(size), -1);
  for (int i = 0; i < size; ++i) {
    if (const auto cr = pane_to_slice(p, s, i + 0.5, p.y0 + 0.5 * p.px_per_row))
      col[std::size_t(i)] = std::clamp(int(std::lround((*cr)[0])), 0, s.width - 1);
    if (const auto cr = pane_to_slice(p, s, p.x0 + 0.5 * p.px_per_col, i + 0.5))
      row[std::size_t(i)] = std::clamp(int(std::lround((*cr)[1])), 0, s.height - 1);
  }
  for (int y = 0; y < size; ++y) {
    if (row[std::size_t(y)] < 0) continue;
    const std::uint32_t* src = s.rgba.data() + std::size_t(row[std::size_t(y)]) * std::size_t(s.width);
    std::uint32_t* dst = p.rgba.data() + std::size_t(y) * std::size_t(size);
    for (int x = 0; x < size; ++x)
      if (col[std::size_t(x)] >= 0) dst[x] = src[col[std::size_t(x)]];
  }
}

SlicePane make_pane(const SliceImage& s, const Vec3& spacing_m, int size) {
  SlicePane p;
  p.size = size;
  p.rgba.assign(std::size_t(size) * std::size_t(size), 0xFF000000u);
  const double wc = s.width * spacing_m[s.axes.col], hr = s.height * spacing_m[s.axes.row];  // physical size [m]
  const double m = 4;  // margin [pixels], room for the letters' outline
  const double scale = (size - 2 * m) / std::max(wc, hr);  // pixels per metre
  p.px_per_col = scale * spacing_m[s.axes.col];
  p.px_per_row = scale * spacing_m[s.axes.row];
  p.x0 = 0.5 * (size - s.width * p.px_per_col);
  p.y0 = 0.5 * (size - s.height * p.px_per_row);
  resample_into(p, s);
  // The marks again at the pane's resolution (a voxel may be less than a pixel there).
  for (const auto& [at, rgba] : {std::pair{s.proxy, kProxyRgba}, std::pair{s.hip, kHipRgba}}) {
    if (at[0] < 0 || at[1] < 0 || at[0] >= s.width || at[1] >= s.height) continue;
    const int cx = int(p.x0 + (at[0] + 0.5) * p.px_per_col), cy = int(p.y0 + (at[1] + 0.5) * p.px_per_row);
    for (int d = -6; d <= 6; ++d)
      for (const auto& [x, y] : {std::array<int, 2>{cx + d, cy}, std::array<int, 2>{cx, cy + d}})
        if (x >= 0 && y >= 0 && x < size && y < size) p.rgba[std::size_t(y) * std::size_t(size) + std::size_t(x)] = rgba;
  }
  const int ts = size >= 192 ? 2 : 1;  // font pixels
  const auto& e = s.axes.edges;
  draw_text(p, std::string(1, e[0]), (size - text_width("A", ts)) / 2, 2, ts);
  draw_text(p, std::string(1, e[1]), (size - text_width("A", ts)) / 2, size - 2 - 7 * ts, ts);
  draw_text(p, std::string(1, e[2]), 2, (size - 7 * ts) / 2, ts);
  draw_text(p, std::string(1, e[3]), size - 2 - text_width("A", ts), (size - 7 * ts) / 2, ts);
  static constexpr const char* kNames[3] = {"AX", "COR", "SAG"};
  draw_text(p, kNames[int(s.kind)], 2, 2, ts);
  return p;
}

std::optional<std::array<double, 2>> pane_to_slice(const SlicePane& p, const SliceImage& s, double x, double y) {
  const double c = (x - p.x0) / p.px_per_col - 0.5, r = (y - p.y0) / p.px_per_row - 0.5;
  if (c < -0.5 || r < -0.5 || c >= s.width - 0.5 || r >= s.height - 0.5) return std::nullopt;
  return std::array<double, 2>{c, r};
}

}  // namespace isotouch::sculpt
