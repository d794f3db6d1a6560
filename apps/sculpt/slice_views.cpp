#include "isotouch/apps/sculpt/slice_views.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "isotouch/run/picture.h"

#if ISOTOUCH_WITH_IMGUI
#include <imgui.h>
#endif

namespace isotouch::sculpt {

using core::Vec3;

void SliceViews::open(const engine::Volume& vol, const core::Isosurface& iso, bool hounsfield) {
  grid_ = vol.grid;
  iso_ = iso;
  for (SliceKind k : kSliceKinds) axes_[std::size_t(k)] = slice_axes(vol.direction, k);
  control_.lo = vol.min_value;
  control_.hi = vol.max_value;
  control_.wl = default_window(vol.min_value, vol.max_value, hounsfield, iso.tau);
  control_.presets = hounsfield ? ct_windows() : std::vector<std::pair<std::string, WindowLevel>>{};
  control_.presets.insert(control_.presets.begin(), {"range", default_window(vol.min_value, vol.max_value, false, 0)});
  shown_.reset();
  plain_key_ = {};
}

void SliceViews::set_labels(const std::vector<std::uint8_t>* ids, const std::vector<float>* before,
                            MaterialsControl materials) {
  labels_.ids = ids;
  labels_.before = before;
  materials_ = std::move(materials);
  shown_.reset();
  plain_key_ = {};
}

std::vector<std::uint32_t> material_rgba(const MaterialsControl& c) {
  std::vector<std::uint32_t> out(1, 0);
  for (const MaterialRow& r : c.rows) {
    const std::uint32_t rgba = label_rgba(r.color);
    out.push_back(r.visible ? rgba : rgba & 0x00FFFFFFu);
  }
  return out;
}

int SliceViews::pane_size(const std::array<int, 2>& fb) { return std::max(16, std::min(fb[1] / 3, fb[0] / 4)); }

bool SliceViews::update(const std::vector<float>& voxels, const Vec3& hip_index, const Vec3& proxy_index, long edits,
                        const std::array<int, 2>& fb) {
  Key key;
  for (int a = 0; a < 3; ++a) {
    key.voxels[std::size_t(a)] = std::lround(hip_index[a]);
    key.voxels[std::size_t(3 + a)] = std::lround(proxy_index[a]);
  }
  key.edits = edits;
  key.wl = control_.wl;
  key.fb = fb;
  if (labels_.ids) key.colours = material_rgba(materials_);
  if (shown_ && *shown_ == key) return false;
  labels_.rgba = key.colours;
  shown_ = key;
  fb_ = fb;
  size_ = pane_size(fb);
  column_.assign(std::size_t(size_) * std::size_t(3 * size_), 0xFF000000u);
  const SliceStyle plain{control_.wl, iso_, false, labels_.ids ? &labels_ : nullptr};
  for (SliceKind k : kSliceKinds) {
    const std::size_t i = std::size_t(k);
    const int normal = axes_[i].normal;
    const PlainKey pk{std::clamp(int(std::lround(hip_index[normal])), 0, grid_.dims[std::size_t(normal)] - 1), edits,
                      control_.wl, key.colours};
    if (plain_key_[i] != pk) {
      plain_[i] = make_slice(grid_, voxels, k, axes_[i], hip_index, proxy_index, plain);
      plain_key_[i] = pk;
    }
    images_[i] = plain_[i];
    mark_slice(images_[i], hip_index, proxy_index, true);
    panes_[i] = make_pane(images_[i], grid_.spacing_m, size_);
    std::copy(panes_[i].rgba.begin(), panes_[i].rgba.end(), column_.begin() + long(i * panes_[i].rgba.size()));
  }
  return true;
}

std::optional<std::pair<SliceKind, Vec3>> SliceViews::hit(double x, double y) const {
  if (column_.empty() || x < column_x() || x >= fb_[0] || y < 0 || y >= 3 * size_) return std::nullopt;
  const std::size_t i = std::size_t(std::clamp(int(y) / size_, 0, 2));
  const auto cr = pane_to_slice(panes_[i], images_[i], x - column_x(), y - double(i) * size_);
  if (!cr) return std::nullopt;
  return std::make_pair(kSliceKinds[i], slice_pixel_index(images_[i], (*cr)[0], (*cr)[1]));
}

void SliceViews::compose(std::vector<std::uint32_t>& picture, int w, int h) const {
  if (column_.empty()) return;
  const int x0 = w - size_;
  for (int y = 0; y < std::min(h, 3 * size_); ++y)
    for (int x = std::max(0, x0); x < w; ++x)
      picture[std::size_t(y) * std::size_t(w) + std::size_t(x)] = column_[std::size_t(y) * std::size_t(size_) + std::size_t(x - x0)];
}

namespace {

std::string json_pair(const std::array<int, 2>& p) {
  std::ostringstream s;
  s << "[" << p[0] << ", " << p[1] << "]";
  return s.str();
}

/// One slice's entry in slices.json.
std::string slice_json(const SliceImage& s, const SlicePane& p, int pane_y) {
  std::ostringstream j;
  j << std::setprecision(10) << "{\"normal_axis\": " << s.axes.normal << ", \"index\": " << s.index
    << ", \"col_axis\": " << s.axes.col << ", \"col_flip\": " << (s.axes.col_flip ? "true" : "false")
    << ", \"row_axis\": " << s.axes.row << ", \"row_flip\": " << (s.axes.row_flip ? "true" : "false")
    << ", \"width\": " << s.width << ", \"height\": " << s.height << ", \"edges\": \"" << std::string(s.axes.edges.begin(), s.axes.edges.end())
    << "\", \"hip_pixel\": " << json_pair(s.hip) << ", \"proxy_pixel\": " << json_pair(s.proxy)
    << ", \"pane\": {\"y\": " << pane_y << ", \"size\": " << p.size << ", \"x0\": " << p.x0 << ", \"y0\": " << p.y0
    << ", \"px_per_col\": " << p.px_per_col << ", \"px_per_row\": " << p.px_per_row << "}}";
  return j.str();
}

}  // namespace

void SliceViews::dump(const std::string& dir, const Vec3& hip_phys_mm) const {
  if (column_.empty()) throw std::runtime_error("--slices-png " + dir + ": no slice computed yet");
  std::filesystem::create_directories(dir);
  std::ostringstream j;
  j << std::setprecision(10) << "{\"isovalue\": " << iso_.tau << ", \"inside\": \"" << core::to_string(iso_.inside)
    << "\", \"level\": " << control_.wl.level << ", \"window\": " << control_.wl.window << ", \"hip_phys_mm\": ["
    << hip_phys_mm.x << ", " << hip_phys_mm.y << ", " << hip_phys_mm.z << "], \"column_x\": " << column_x();
  for (SliceKind k : kSliceKinds) {
    const std::size_t i = std::size_t(k);
    run::write_png((std::filesystem::path(dir) / (std::string(to_string(k)) + ".png")).string(), images_[i].width,
                   images_[i].height, images_[i].rgba);
    j << ", \"" << to_string(k) << "\": " << slice_json(images_[i], panes_[i], int(i) * size_);
  }
  j << "}\n";
  const std::string path = (std::filesystem::path(dir) / "slices.json").string();
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << j.str();
    if (!out.flush()) throw std::runtime_error(tmp + ": cannot write");
  }
  std::filesystem::rename(tmp, path);
}

#if ISOTOUCH_WITH_IMGUI
void slice_widgets(SliceControl& c) {
  if (!c.shown || !(c.hi > c.lo)) return;
  ImGui::Separator();
  ImGui::TextUnformatted("slice views (window / level)");
  float level = float(c.wl.level), window = float(c.wl.window);
  const float span = float(c.hi - c.lo);
  if (ImGui::SliderFloat("level", &level, float(c.lo), float(c.hi), "%.0f")) c.wl.level = level;
  if (ImGui::SliderFloat("window", &window, 1e-3f * span, 2.0f * span, "%.0f", ImGuiSliderFlags_Logarithmic))
    c.wl.window = std::max(double(window), 1e-6 * double(span));
  for (std::size_t i = 0; i < c.presets.size(); ++i) {
    if (i > 0) ImGui::SameLine();
    if (ImGui::Button((c.presets[i].first + "##wl").c_str())) c.wl = c.presets[i].second;
  }
}
void material_widgets(MaterialsControl& c) {
  if (c.rows.empty()) return;
  ImGui::Separator();
  ImGui::TextUnformatted("materials (shown in the slice views, colour)");
  for (std::size_t i = 0; i < c.rows.size(); ++i) {
    MaterialRow& r = c.rows[i];
    ImGui::PushID(int(i));
    ImGui::Checkbox("##visible", &r.visible);
    ImGui::SameLine();
    // ImGui edits floats: the scene's colour (doubles) is replaced only when the user picks one.
    float rgb[3] = {float(r.color[0]), float(r.color[1]), float(r.color[2])};
    if (ImGui::ColorEdit3("##colour", rgb, ImGuiColorEditFlags_NoInputs))
      r.color = {double(rgb[0]), double(rgb[1]), double(rgb[2])};
    ImGui::SameLine();
    ImGui::Text("%s  K %.0f N/m", r.name.c_str(), r.stiffness_n_per_m);
    if (ImGui::IsItemHovered()) ImGui::SetTooltip("%ld voxels as loaded", r.voxels);
    if (r.critical) {
      ImGui::SameLine();
      ImGui::TextColored(ImVec4(1.0f, 0.35f, 0.3f, 1.0f), "critical, %.1f mm", r.margin_mm);
    }
    ImGui::PopID();
  }
}
#else
void slice_widgets(SliceControl&) {}
void material_widgets(MaterialsControl&) {}
#endif

}  // namespace isotouch::sculpt
