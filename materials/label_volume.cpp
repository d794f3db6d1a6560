#include "isotouch/materials/label_volume.h"

#include <cmath>
#include <map>
#include <sstream>

#include "isotouch/io/volume_io.h"
#include "isotouch/materials/seg_nrrd.h"

namespace isotouch::materials {
namespace {

std::string vox(int x, int y, int z) {
  return "(" + std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) + ")";
}

std::string num(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

/// Every voxel of `map` as a whole label value in [0, 65535].
std::vector<int> label_values(const engine::Volume& map) {
  std::vector<int> out(map.voxels.size());
  const auto& d = map.grid.dims;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const float v = map.voxels[i];
    if (!(v >= 0.f && v <= 65535.f) || v != std::floor(v)) {
      const int x = int(i % std::size_t(d[0])), y = int(i / std::size_t(d[0]) % std::size_t(d[1])),
                z = int(i / (std::size_t(d[0]) * std::size_t(d[1])));
      throw MaterialError(map.path + ": voxel " + vox(x, y, z) + " holds " + num(v) + " (voxel type " +
                          map.component_type + "): a label map holds whole label values in [0, 65535]");
    }
    out[i] = int(v);
  }
  return out;
}

bool same_grid(const engine::Volume& a, const engine::Volume& b) {
  if (a.grid.dims != b.grid.dims) return false;
  for (int k = 0; k < 3; ++k) {
    const double s = a.grid.spacing_m[k];
    if (std::abs(a.grid.spacing_m[k] - b.grid.spacing_m[k]) > 1e-6 * s ||
        std::abs(a.grid.origin_m[k] - b.grid.origin_m[k]) > 1e-3 * s)
      return false;
  }
  for (int k = 0; k < 9; ++k)
    if (std::abs(a.direction[std::size_t(k)] - b.direction[std::size_t(k)]) > 1e-6) return false;
  return true;
}

std::string grid_text(const engine::Volume& v) {
  const auto& g = v.grid;
  return std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" + std::to_string(g.dims[2]) + " voxels of " +
         num(g.spacing_m.x * 1e3) + " x " + num(g.spacing_m.y * 1e3) + " x " + num(g.spacing_m.z * 1e3) + " mm at (" +
         num(g.origin_m.x * 1e3) + ", " + num(g.origin_m.y * 1e3) + ", " + num(g.origin_m.z * 1e3) + ") mm";
}

/// The label value of every scan voxel, resampled (nearest neighbour) when the grids differ.
std::vector<int> on_scan_grid(const engine::Volume& map, const std::vector<int>& values, const engine::Volume& scan,
                              LabelVolume& out) {
  if (same_grid(map, scan)) return values;
  const auto& sd = scan.grid.dims;
  const auto& md = map.grid.dims;
  std::vector<int> res(scan.grid.voxel_count(), 0);
  std::size_t inside = 0;
  for (int z = 0; z < sd[2]; ++z)
    for (int y = 0; y < sd[1]; ++y)
      for (int x = 0; x < sd[0]; ++x) {
        const core::Vec3 idx = map.grid.to_index(map.to_grid(scan.index_to_physical({double(x), double(y), double(z)})));
        const long i = std::lround(idx.x), j = std::lround(idx.y), k = std::lround(idx.z);
        if (i < 0 || j < 0 || k < 0 || i >= md[0] || j >= md[1] || k >= md[2]) continue;
        res[scan.grid.index(x, y, z)] = values[map.grid.index(int(i), int(j), int(k))];
        ++inside;
      }
  if (inside == 0)
    throw MaterialError(map.path + ": grid mismatch: the label map (" + grid_text(map) +
                        ") covers no voxel of the scan (" + grid_text(scan) + ")");
  out.notes.push_back(map.path + ": the label map's grid (" + grid_text(map) + ") is not the scan's (" +
                      grid_text(scan) + "): resampled onto the scan's grid, nearest neighbour (" +
                      std::to_string(inside) + " of " + std::to_string(res.size()) + " scan voxels inside the map)");
  return res;
}

/// Fills in each material's label (and colour) from the segments of a `.seg.nrrd`.
void from_segments(const std::string& path, std::vector<Material>& list) {
  const std::vector<Segment> segs = parse_seg_nrrd_segments(io::header_text_fields(path), path);
  for (std::size_t i = 0; i < list.size(); ++i) {
    Material& m = list[i];
    const Segment* hit = nullptr;
    for (const Segment& s : segs)
      if (m.label >= 0 ? s.label_value == m.label : s.name == m.name) hit = &s;
    if (!hit) {
      std::string names;
      for (const Segment& s : segs) names += (names.empty() ? "" : ", ") + s.name + " = " + std::to_string(s.label_value);
      throw MaterialError(path + ": materials.list[" + std::to_string(i) + "] \"" + m.name + "\"" +
                          (m.label >= 0 ? " (label " + std::to_string(m.label) + ")" : "") +
                          ": no segment of that " + (m.label >= 0 ? "label value" : "name") + " (segments: " + names + ")");
    }
    m.label = hit->label_value;
    if (!m.has_color) m.color = hit->color;
  }
}

/// Ids from label values; a non-zero value no material claims, or one two materials claim
/// (one written in the scene, one filled in from its segment), is an error.
void to_ids(const std::string& path, const std::vector<int>& values, const engine::Volume& scan, LabelVolume& out) {
  std::map<int, std::uint8_t> id_of;
  std::string known;
  for (std::size_t i = 0; i < out.materials.size(); ++i) {
    const auto [at, fresh] = id_of.emplace(out.materials[i].label, std::uint8_t(i + 1));
    if (!fresh)
      throw MaterialError(path + ": materials.list[" + std::to_string(i) + "] \"" + out.materials[i].name +
                          "\" and materials.list[" + std::to_string(at->second - 1) + "] \"" +
                          out.materials[at->second - 1].name + "\" both have label value " +
                          std::to_string(out.materials[i].label));
    known += (known.empty() ? "" : ", ") + std::to_string(out.materials[i].label);
  }
  const auto& d = scan.grid.dims;
  out.ids.resize(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (values[i] == 0) continue;
    const auto it = id_of.find(values[i]);
    if (it == id_of.end()) {
      const int x = int(i % std::size_t(d[0])), y = int(i / std::size_t(d[0]) % std::size_t(d[1])),
                z = int(i / (std::size_t(d[0]) * std::size_t(d[1])));
      throw MaterialError(path + ": label value " + std::to_string(values[i]) + " (first at scan voxel " + vox(x, y, z) +
                          ") is no material's: materials.list has labels " + known);
    }
    out.ids[i] = it->second;
  }
}

void from_transfer(const engine::Volume& scan, LabelVolume& out) {
  out.ids.assign(scan.voxels.size(), 0);
  for (std::size_t i = 0; i < scan.voxels.size(); ++i)
    for (std::size_t m = 0; m < out.materials.size(); ++m)
      if (scan.voxels[i] >= out.materials[m].range_lo && scan.voxels[i] < out.materials[m].range_hi) {
        out.ids[i] = std::uint8_t(m + 1);
        break;
      }
}

}  // namespace

LabelVolume load_label_volume(const MaterialsSpec& spec, const engine::Volume& scan) {
  if (spec.list.empty() || spec.list.size() > kMaxMaterials)
    throw MaterialError("materials.list: " + std::to_string(spec.list.size()) + " materials, must be 1 to " +
                        std::to_string(kMaxMaterials));
  LabelVolume out;
  out.grid = scan.grid;
  out.materials = spec.list;
  if (spec.labels_path.empty()) {
    out.source = "transfer function";
    from_transfer(scan, out);
  } else {
    const bool seg = is_seg_nrrd(spec.labels_path);
    out.source = (seg ? "3D Slicer segmentation " : "label map ") + spec.labels_path;
    // The voxels first: an unreadable file is named by the volume reader, not taken for a
    // header without segments.
    const engine::Volume map = io::load_volume(spec.labels_path);
    if (seg) from_segments(spec.labels_path, out.materials);
    to_ids(spec.labels_path, on_scan_grid(map, label_values(map), scan, out), scan, out);
  }
  out.voxels.assign(out.materials.size() + 1, 0);
  for (std::uint8_t id : out.ids) ++out.voxels[id];
  for (std::size_t m = 0; m < out.materials.size(); ++m)
    if (out.voxels[m + 1] == 0) out.notes.push_back(out.source + ": material \"" + out.materials[m].name + "\" holds no voxel");
  return out;
}

}  // namespace isotouch::materials
