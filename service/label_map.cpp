#include "isotouch/service/label_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>

namespace isotouch::service {
namespace {

[[noreturn]] void refuse(const std::string& device, const std::string& why) {
  throw engine::VolumeError("igtl:" + device + ": " + why);
}

std::string num(double v) {
  std::ostringstream o;
  o.precision(9);
  o << v;
  return o.str();
}

std::string dims_text(const core::Grid& g) {
  return std::to_string(g.dims[0]) + " x " + std::to_string(g.dims[1]) + " x " + std::to_string(g.dims[2]);
}

double axis(const core::Vec3& v, int a) { return a == 0 ? v.x : a == 1 ? v.y : v.z; }

/// The label map's grid against the session volume's: same dims, spacing, origin, direction.
void check_grid(const engine::Volume& l, const std::string& dev, const engine::Volume& f) {
  const char* xyz = "xyz";
  if (l.grid.dims != f.grid.dims)
    refuse(dev, "label map dimensions " + dims_text(l.grid) + " are not the volume's " + dims_text(f.grid) +
                    " (a label map must lie on the session volume's grid)");
  double smallest = 1e300;
  for (int a = 0; a < 3; ++a) {
    const double ls = axis(l.grid.spacing_m, a) * 1e3, fs = axis(f.grid.spacing_m, a) * 1e3;
    smallest = std::min(smallest, fs);
    if (!(std::abs(ls - fs) <= kLabelSpacingTolerance * fs))
      refuse(dev, std::string("label map spacing along ") + xyz[a] + " is " + num(ls) + " mm, the volume's " + num(fs) +
                      " mm");
  }
  for (int a = 0; a < 3; ++a) {
    const double lo = axis(l.grid.origin_m, a) * 1e3, fo = axis(f.grid.origin_m, a) * 1e3;
    if (!(std::abs(lo - fo) <= kLabelOriginTolerance * smallest))
      refuse(dev, std::string("label map origin along ") + xyz[a] + " is " + num(lo) + " mm (LPS), the volume's " +
                      num(fo) + " mm");
  }
  for (std::size_t i = 0; i < 9; ++i)
    if (!(std::abs(l.direction[i] - f.direction[i]) <= kLabelDirectionTolerance))
      refuse(dev, "label map direction cosine (row " + std::to_string(i / 3) + ", column " + std::to_string(i % 3) +
                      ") is " + num(l.direction[i]) + ", the volume's " + num(f.direction[i]));
}

std::string colour_text(const std::array<double, 3>& c) {
  char b[8];
  std::snprintf(b, sizeof b, "#%02x%02x%02x", int(std::lround(c[0] * 255)) & 255, int(std::lround(c[1] * 255)) & 255,
                int(std::lround(c[2] * 255)) & 255);
  return b;
}

}  // namespace

materials::LabelVolume labels_from_image(const engine::Volume& labels, const std::string& device,
                                         const std::vector<LabelMetaEntry>& meta, const engine::Volume& frame,
                                         const std::vector<materials::Material>& scene) {
  if (meta.empty()) refuse(device, "no LBMETA element names this label map");
  check_grid(labels, device, frame);
  materials::LabelVolume lv;
  lv.grid = frame.grid;
  lv.source = "label map IMAGE '" + device + "' (LBMETA)";
  std::map<int, std::uint8_t> id_of;  // label value -> material id
  std::set<std::string> names;
  for (const LabelMetaEntry& e : meta) {
    if (e.label == 0)
      refuse(device, "LBMETA label '" + e.name + "' has label value 0, the background (no material)");
    if (id_of.count(e.label))
      refuse(device, "LBMETA labels '" + lv.materials[id_of[e.label] - 1u].name + "' and '" + e.name +
                         "' have one label value, " + std::to_string(e.label));
    if (!names.insert(e.name).second) refuse(device, "LBMETA names two labels '" + e.name + "'");
    materials::Material m;
    const auto same = std::find_if(scene.begin(), scene.end(), [&](const materials::Material& s) { return s.name == e.name; });
    if (same != scene.end()) {
      m = *same;
      lv.notes.push_back("'" + e.name + "' takes the scene's material of that name (K, friction, rate, density_scale, "
                         "critical, margin)");
    }
    m.name = e.name;
    m.label = e.label;
    m.color = {e.rgba[0] / 255.0, e.rgba[1] / 255.0, e.rgba[2] / 255.0};
    m.has_color = true;
    m.range_lo = m.range_hi = 0;
    lv.materials.push_back(m);
    id_of[e.label] = std::uint8_t(lv.materials.size());
  }
  std::array<std::uint8_t, 256> table{};  // label value -> id; 0: none (value 0) or no label
  for (const auto& [value, id] : id_of) table[std::size_t(value)] = id;
  const auto& d = labels.grid.dims;
  lv.ids.resize(labels.voxels.size());
  lv.voxels.assign(lv.materials.size() + 1, 0);
  for (std::size_t i = 0; i < labels.voxels.size(); ++i) {
    const float v = labels.voxels[i];
    const bool known = v >= 0.f && v <= 255.f && v == std::floor(v) && (v == 0.f || table[std::size_t(v)] != 0);
    if (!known) {
      const std::size_t x = i % std::size_t(d[0]), y = i / std::size_t(d[0]) % std::size_t(d[1]),
                        z = i / (std::size_t(d[0]) * std::size_t(d[1]));
      std::string have;
      for (const materials::Material& m : lv.materials) have += (have.empty() ? "" : ", ") + std::to_string(m.label);
      refuse(device, "label value " + num(v) + " (voxel (" + std::to_string(x) + ", " + std::to_string(y) + ", " +
                         std::to_string(z) + ")) is no label of the LBMETA (its label values: " + have + ")");
    }
    const std::uint8_t id = table[std::size_t(v)];
    lv.ids[i] = id;
    ++lv.voxels[id];
  }
  for (std::size_t i = 0; i < lv.materials.size(); ++i)
    if (lv.voxels[i + 1] == 0)
      lv.notes.push_back("'" + lv.materials[i].name + "' (label " + std::to_string(lv.materials[i].label) +
                         ") holds no voxel");
  return lv;
}

std::string describe_materials(const materials::LabelVolume& lv) {
  std::string s;
  for (std::size_t i = 0; i < lv.materials.size(); ++i) {
    const materials::Material& m = lv.materials[i];
    s += (i ? ", " : "") + m.name + " (label " + std::to_string(m.label) + ", colour " + colour_text(m.color) + ", " +
         std::to_string(lv.voxels[i + 1]) + " voxels" + (m.critical ? ", critical" : "") + ")";
  }
  return s;
}

}  // namespace isotouch::service
