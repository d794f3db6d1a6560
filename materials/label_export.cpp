#include "isotouch/materials/label_export.h"

#include <zlib.h>

#include <algorithm>
#include <charconv>
#include <locale>
#include <set>
#include <sstream>

#include "isotouch/io/output_file.h"

namespace isotouch::materials {
namespace {

/// `raw` as one gzip member (NRRD's `encoding: gzip`).
std::string gzip(const std::string& raw, const std::string& path) {
  z_stream z{};
  if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    throw MaterialError(path + ": zlib could not start compressing the labels");
  std::string out(deflateBound(&z, uLong(raw.size())), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(raw.data()));
  z.avail_in = uInt(raw.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = uInt(out.size());
  const int rc = deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  if (rc != Z_STREAM_END) throw MaterialError(path + ": zlib could not compress the labels");
  return out;
}

/// The shortest text that reads back as `v` exactly (0.95, not 0.94999999999999996).
std::string num(double v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, end) : std::string("0");
}

}  // namespace

std::vector<std::uint8_t> edited_ids(const std::vector<std::uint8_t>& ids, const std::vector<float>& before,
                                     const std::vector<float>& after, const core::Isosurface& iso) {
  if (before.size() != ids.size() || after.size() != ids.size())
    throw MaterialError("edited labels: " + std::to_string(ids.size()) + " labels but " + std::to_string(before.size()) +
                        " voxels before the edits and " + std::to_string(after.size()) + " after");
  std::vector<std::uint8_t> out(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) out[i] = edited_id(ids[i], before[i], after[i], iso);
  return out;
}

std::vector<int> export_label_values(const std::vector<Material>& materials) {
  std::vector<int> own, by_id;
  std::set<int> seen;
  bool all_own = true;
  for (std::size_t i = 0; i < materials.size(); ++i) {
    const int l = materials[i].label;
    all_own = all_own && l >= 1 && l <= 65535 && seen.insert(l).second;
    own.push_back(l);
    by_id.push_back(int(i + 1));
  }
  return all_own ? own : by_id;
}

void write_seg_nrrd(const std::string& path, const std::vector<std::uint8_t>& ids, const std::vector<Material>& materials,
                    const engine::Volume& geometry) {
  const core::Grid& g = geometry.grid;
  if (ids.size() != g.voxel_count())
    throw MaterialError(path + ": " + std::to_string(ids.size()) + " labels for a grid of " +
                        std::to_string(g.voxel_count()) + " voxels");
  for (std::size_t i = 0; i < materials.size(); ++i)
    if (materials[i].name.find_first_of("\r\n") != std::string::npos)
      throw MaterialError(path + ": materials.list[" + std::to_string(i) + "].name: a line break cannot go into the header");
  const std::vector<int> values = export_label_values(materials);
  const bool wide = !values.empty() && *std::max_element(values.begin(), values.end()) > 255;
  std::string raw(ids.size() * (wide ? 2 : 1), '\0');
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::uint8_t id = ids[i];
    if (id > materials.size())
      throw MaterialError(path + ": voxel " + std::to_string(i) + " holds material id " + std::to_string(id) + ", only " +
                          std::to_string(materials.size()) + " materials");
    const int v = id == 0 ? 0 : values[id - 1u];
    if (wide) {
      raw[2 * i] = char(v & 0xFF);  // little endian
      raw[2 * i + 1] = char(v >> 8 & 0xFF);
    } else {
      raw[i] = char(v);
    }
  }
  std::ostringstream h;
  h.imbue(std::locale::classic());
  h << "NRRD0004\n"
    << "# Complete NRRD file format specification at:\n"
    << "# http://teem.sourceforge.net/nrrd/format.html\n"
    << "type: " << (wide ? "unsigned short" : "unsigned char") << "\n"
    << "dimension: 3\n"
    << "space: left-posterior-superior\n"
    << "sizes: " << g.dims[0] << " " << g.dims[1] << " " << g.dims[2] << "\n"
    << "space directions:";
  const double sp_mm[3] = {g.spacing_m.x * 1e3, g.spacing_m.y * 1e3, g.spacing_m.z * 1e3};
  for (std::size_t a = 0; a < 3; ++a)  // index axis a: column a of D times its spacing
    h << " (" << num(geometry.direction[a] * sp_mm[a]) << "," << num(geometry.direction[3 + a] * sp_mm[a]) << ","
      << num(geometry.direction[6 + a] * sp_mm[a]) << ")";
  h << "\nkinds: domain domain domain\n";
  if (wide) h << "endian: little\n";
  h << "encoding: gzip\n"
    << "space origin: (" << num(g.origin_m.x * 1e3) << "," << num(g.origin_m.y * 1e3) << "," << num(g.origin_m.z * 1e3) << ")\n";
  for (std::size_t i = 0; i < materials.size(); ++i) {
    const Material& m = materials[i];
    const std::string s = "Segment" + std::to_string(i) + "_";
    h << s << "Color:=" << num(m.color[0]) << " " << num(m.color[1]) << " " << num(m.color[2]) << "\n"
      << s << "ColorAutoGenerated:=0\n"
      << s << "Extent:=0 " << g.dims[0] - 1 << " 0 " << g.dims[1] - 1 << " 0 " << g.dims[2] - 1 << "\n"
      << s << "ID:=Segment_" << values[i] << "\n"
      << s << "LabelValue:=" << values[i] << "\n"
      << s << "Layer:=0\n"
      << s << "Name:=" << m.name << "\n"
      << s << "NameAutoGenerated:=0\n"
      << s << "Tags:=|\n";
  }
  h << "Segmentation_ContainedRepresentationNames:=Binary labelmap|\n"
    << "Segmentation_MasterRepresentation:=Binary labelmap\n"
    << "Segmentation_ReferenceImageExtentOffset:=0 0 0\n"
    << "\n";
  try {
    io::write_output(path, h.str() + gzip(raw, path));
  } catch (const io::OutputError& e) {
    throw MaterialError(e.what());
  }
}

}  // namespace isotouch::materials
