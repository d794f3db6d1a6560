// vdb_io.cpp - OpenVDB in and out, and the isosurface as a mesh (its files: mesh_write.cpp).
// The only translation unit besides openvdb_check.cpp that includes OpenVDB. See vdb_io.h
// for the frames and contracts.
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/scan.h"

#include "isotouch/io/output_file.h"
#include "isotouch/io/volume_write.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <unordered_map>

#ifdef ISOTOUCH_HAVE_OPENVDB
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/VolumeToMesh.h>
#endif

namespace isotouch::io {
namespace {

// ---------------------------------------------------------------------------------------
// Atomic writes: temp file in the target's folder, fsync, rename over the target, fsync
// the folder. A crash (SIGKILL, power loss after the rename's fsync) leaves the old file
// or the new one, never a mix.

/// Writes `path` whole or not at all through the one output writer (io/output_file.h):
/// `write(tmp)` fills a fresh temp file, renamed over a regular file or copied into a
/// device, FIFO or "-".
void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  try {
    io::write_output(path, write);
  } catch (const io::OutputError& e) {
    throw VdbError(e.what());
  }
}

[[maybe_unused]] void require_openvdb(const std::string& path) {
#ifndef ISOTOUCH_HAVE_OPENVDB
  throw VdbError(path + ": built without OpenVDB (Debian: libopenvdb-dev), .vdb and meshes unavailable");
#else
  (void)path;
#endif
}

// Physical frame of a grid-world point (vdb_io.h): origin + D (w - origin).
std::array<double, 3> to_physical(const engine::Volume& v, double wx, double wy, double wz) {
  const auto& o = v.grid.origin_m;
  const double d[3] = {wx - o.x, wy - o.y, wz - o.z};
  const auto& D = v.direction;
  return {o.x + D[0] * d[0] + D[1] * d[1] + D[2] * d[2], o.y + D[3] * d[0] + D[4] * d[1] + D[5] * d[2],
          o.z + D[6] * d[0] + D[7] * d[1] + D[8] * d[2]};
}

double det3(const std::array<double, 9>& m) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
}

#ifdef ISOTOUCH_HAVE_OPENVDB
using openvdb::Coord;
using openvdb::FloatGrid;

constexpr const char* kMetaIso = "isotouch_isovalue";
constexpr const char* kMetaInside = "isotouch_inside";
constexpr const char* kMetaSource = "isotouch_source";
constexpr const char* kMetaBoxMin = "isotouch_box_min";
constexpr const char* kMetaDims = "isotouch_dims";
constexpr const char* kMetaDirection = "isotouch_direction";
constexpr const char* kMetaUnits = "isotouch_units";
constexpr const char* kMetaSpacing = "isotouch_spacing_m";
constexpr const char* kMetaOrigin = "isotouch_origin_m";
constexpr const char* kMetaReader = "isotouch_reader";
constexpr const char* kMetaComponent = "isotouch_component_type";
constexpr const char* kVdbReader = "openvdb:FloatGrid";
constexpr const char* kConvertedFrom = " (converted from ";

/// The reader a volume was first read with: `reader`, or the one in brackets of a .vdb's.
std::string first_reader(const std::string& reader) {
  const std::string prefix = std::string(kVdbReader) + kConvertedFrom;
  if (reader.rfind(prefix, 0) == 0 && reader.back() == ')')
    return reader.substr(prefix.size(), reader.size() - prefix.size() - 1);
  return reader;
}

/// Dense volume -> FloatGrid in index space: voxel (i, j, k) active at Coord(i, j, k) with
/// value `map(v)`. With `shell_tau`, also a 1-voxel layer around it (active), each shell
/// voxel the mirror image about tau of its nearest volume voxel m: 2 tau - m where m is
/// inside (m < tau), so an object touching the border is closed half a voxel beyond the
/// border voxels; the background (outside) where m is outside.
FloatGrid::Ptr dense_to_grid(const engine::Volume& vol, float background, const std::function<float(float)>& map,
                             std::optional<float> shell_tau = std::nullopt) {
  openvdb::initialize();
  FloatGrid::Ptr grid = FloatGrid::create(background);
  auto acc = grid->getAccessor();
  const auto& d = vol.grid.dims;
  const int s = shell_tau ? 1 : 0;
  for (int z = -s; z < d[2] + s; ++z)
    for (int y = -s; y < d[1] + s; ++y)
      for (int x = -s; x < d[0] + s; ++x) {
        const int cx = std::clamp(x, 0, d[0] - 1), cy = std::clamp(y, 0, d[1] - 1), cz = std::clamp(z, 0, d[2] - 1);
        const float m = map(vol.voxels[vol.grid.index(cx, cy, cz)]);
        float value = m;
        if (cx != x || cy != y || cz != z) {
          const double mirror = 2.0 * double(*shell_tau) - double(m);
          value = m < *shell_tau ? float(std::min(mirror, double(std::numeric_limits<float>::max()))) : background;
        }
        acc.setValueOn(Coord(x, y, z), value);
      }
  return grid;
}

std::string transform_text(const openvdb::math::Transform& t) {
  std::ostringstream s;
  s << t.mapType() << " " << t.baseMap()->str();
  std::string r = s.str();
  std::replace(r.begin(), r.end(), '\n', ' ');
  return r;
}

/// The grid-world frame of a grid: its transform must be world = scale * index + t with a
/// positive, axis-aligned scale.
void grid_frame(const openvdb::GridBase& g, const std::string& path, openvdb::Vec3d& scale, openvdb::Vec3d& trans) {
  const auto& t = g.transform();
  const std::string where = path + ": grid '" + g.getName() + "': ";
  if (!t.isLinear())
    throw VdbError(where + "transform is not linear (" + transform_text(t) + "); only a scale + translation is supported");
  const openvdb::Mat4d m = t.baseMap()->getAffineMap()->getConstMat4();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (r != c && m(r, c) != 0.0)
        throw VdbError(where + "transform has a rotation or shear (" + transform_text(t) +
                       "); only an axis-aligned scale + translation is supported");
  for (int a = 0; a < 3; ++a) {
    scale[a] = m(a, a);
    trans[a] = m(3, a);
    if (!(scale[a] > 0.0) || !std::isfinite(scale[a]) || !std::isfinite(trans[a]))
      throw VdbError(where + "transform scale must be finite and positive on every axis (" + transform_text(t) + ")");
  }
}

std::string list_grids(const openvdb::GridPtrVec& grids) {
  std::string s;
  for (const auto& g : grids) s += (s.empty() ? "" : ", ") + ("'" + g->getName() + "' (" + g->valueType() + ")");
  return s.empty() ? "none" : s;
}


/// The limits every volume meets (io::check_volume_limits, io::check_direction), checked on
/// the box, transform and direction before the dense voxels are allocated.
void check_limits(const std::string& path, const std::string& grid, const engine::Volume& v) {
  const auto& g = v.grid;
  const VolumeFields fields{"active bounding box (isotouch_dims)", "transform scale (voxel size)",
                            "transform translation (origin)", "isotouch_direction"};
  try {
    io::check_volume_limits(path, {std::uint64_t(g.dims[0]), std::uint64_t(g.dims[1]), std::uint64_t(g.dims[2])},
                            {g.spacing_m.x * 1e3, g.spacing_m.y * 1e3, g.spacing_m.z * 1e3},
                            {g.origin_m.x * 1e3, g.origin_m.y * 1e3, g.origin_m.z * 1e3}, 0, "float", fields);
    io::check_direction(path, v.direction, fields.direction);
  } catch (const engine::VolumeError& e) {
    throw VdbError(path + ": grid '" + grid + "': " + std::string(e.what()).substr(path.size() + 2));
  }
}

template <typename MetaT>
typename MetaT::ConstPtr meta(const openvdb::GridBase& g, const char* key) {
  return g.getMetadata<MetaT>(key);
}
#endif

}  // namespace

// ---------------------------------------------------------------------------------------
// .vdb in

LoadedVdb load_vdb(const std::string& path, const std::string& grid_name, std::uint64_t max_voxels) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw VdbError(path + ": no such file");
  try {
    require_regular_file(path, "a .vdb volume is read from a regular file");
  } catch (const engine::VolumeError& e) {
    throw VdbError(e.what());
  }
  require_openvdb(path);
  LoadedVdb out;
#ifdef ISOTOUCH_HAVE_OPENVDB
  openvdb::initialize();
  openvdb::GridPtrVecPtr grids;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    grids = file.getGrids();
    file.close();
  } catch (const openvdb::Exception& e) {
    throw VdbError(path + ": not a readable OpenVDB file (" + e.what() + ")");
  }
  FloatGrid::Ptr grid;
  for (const auto& g : *grids) {
    if (!grid_name.empty() && g->getName() != grid_name) continue;
    grid = openvdb::gridPtrCast<FloatGrid>(g);
    if (!grid_name.empty() && !grid)
      throw VdbError(path + ": grid '" + grid_name + "' holds " + g->valueType() + ", not float");
    if (grid) break;
  }
  if (!grid) {
    if (!grid_name.empty()) throw VdbError(path + ": no grid named '" + grid_name + "' (grids: " + list_grids(*grids) + ")");
    throw VdbError(path + ": no float grid (grids: " + list_grids(*grids) + ")");
  }
  out.grid_name = grid->getName();
  const std::string where = path + ": grid '" + out.grid_name + "': ";
  out.grid_class = FloatGrid::gridClassToString(grid->getGridClass());
  out.background = grid->background();
  if (grid->activeVoxelCount() == 0) throw VdbError(where + "empty (no active voxel)");
  openvdb::Vec3d scale, trans;
  grid_frame(*grid, path, scale, trans);

  // The box: save_vdb's own (metadata), else the active bbox + margin, 8-aligned. Corners
  // and extents are computed in 64 bits: a crafted file's box may span 2^31 voxels, whose
  // int32 extent (and the voxel count from it) would wrap.
  std::array<std::int64_t, 3> lo{}, hi{};
  const auto box_min = meta<openvdb::Vec3IMetadata>(*grid, kMetaBoxMin);
  const auto box_dims = meta<openvdb::Vec3IMetadata>(*grid, kMetaDims);
  const openvdb::CoordBBox active = grid->evalActiveVoxelBoundingBox();
  const auto inside_int32 = [](std::int64_t v) { return v >= INT32_MIN && v <= INT32_MAX; };
  if (box_min && box_dims && box_dims->value().x() > 0 && box_dims->value().y() > 0 && box_dims->value().z() > 0) {
    const openvdb::Vec3i bl = box_min->value(), bn = box_dims->value();
    bool fits = true;
    for (int a = 0; a < 3; ++a) {
      lo[std::size_t(a)] = bl[a];
      hi[std::size_t(a)] = std::int64_t(bl[a]) + bn[a] - 1;
      fits = fits && inside_int32(hi[std::size_t(a)]);
    }
    // Only while the saved box still holds every active voxel (not edited by another tool).
    out.written_by_isotouch =
        fits && openvdb::CoordBBox{Coord{int(lo[0]), int(lo[1]), int(lo[2])}, Coord{int(hi[0]), int(hi[1]), int(hi[2])}}
                    .isInside(active);
  }
  if (!out.written_by_isotouch) {
    for (int a = 0; a < 3; ++a) {
      const auto f8 = [](std::int64_t v) { return v >= 0 ? v / 8 * 8 : -((-v + 7) / 8 * 8); };
      lo[std::size_t(a)] = f8(std::int64_t(active.min()[a]) - kVdbLoadMarginVox);
      hi[std::size_t(a)] = f8(std::int64_t(active.max()[a]) + kVdbLoadMarginVox) + 7;
    }
  }
  const std::array<std::int64_t, 3> ext{hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1};
  const bool each_ok = ext[0] <= (1 << 20) && ext[1] <= (1 << 20) && ext[2] <= (1 << 20) &&
                       inside_int32(lo[0]) && inside_int32(lo[1]) && inside_int32(lo[2]) && inside_int32(hi[0]) &&
                       inside_int32(hi[1]) && inside_int32(hi[2]);
  const std::uint64_t n = each_ok ? std::uint64_t(ext[0]) * std::uint64_t(ext[1]) * std::uint64_t(ext[2]) : 0;
  if (!each_ok || n > max_voxels) {
    std::ostringstream s;
    s << where << "bounding box [" << lo[0] << ", " << lo[1] << ", " << lo[2] << "] -> [" << hi[0] << ", " << hi[1] << ", "
      << hi[2] << "] is " << ext[0] << " x " << ext[1] << " x " << ext[2] << " voxels, above the limit of "
      << max_voxels << " voxels (and 2^20 per axis) for a dense volume";
    throw VdbError(s.str());
  }
  const openvdb::CoordBBox box{Coord{int(lo[0]), int(lo[1]), int(lo[2])}, Coord{int(hi[0]), int(hi[1]), int(hi[2])}};

  engine::Volume& v = out.volume;
  v.grid.dims = {int(ext[0]), int(ext[1]), int(ext[2])};
  v.grid.spacing_m = {scale[0], scale[1], scale[2]};
  v.grid.origin_m = {scale[0] * box.min().x() + trans[0], scale[1] * box.min().y() + trans[1],
                     scale[2] * box.min().z() + trans[2]};
  // OpenVDB's Transform(map) re-derives the scale as (s + t) - t, off by an ULP or so: the
  // exact spacing and origin travel in save_vdb's metadata, used while the transform agrees.
  const auto exact_s = meta<openvdb::Vec3DMetadata>(*grid, kMetaSpacing);
  const auto exact_o = meta<openvdb::Vec3DMetadata>(*grid, kMetaOrigin);
  if (out.written_by_isotouch && exact_s && exact_o && box.min() == Coord(0, 0, 0)) {
    const openvdb::Vec3d es = exact_s->value(), eo = exact_o->value();
    bool agree = true;
    for (int a = 0; a < 3; ++a)
      agree = agree && std::abs(es[a] - scale[a]) <= 1e-9 * std::abs(es[a]) &&
              std::abs(eo[a] - trans[a]) <= 1e-9 * (std::abs(eo[a]) + std::abs(es[a]));
    if (agree) {
      v.grid.spacing_m = {es[0], es[1], es[2]};
      v.grid.origin_m = {eo[0], eo[1], eo[2]};
    }
  }
  if (const auto d = meta<openvdb::Mat4DMetadata>(*grid, kMetaDirection)) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.direction[std::size_t(3 * r + c)] = d->value()(r, c);
    v.direction_is_identity = v.direction == std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1};
  }
  check_limits(path, out.grid_name, v);
  v.voxels.assign(n, 0.0f);
  {
    openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(box, v.voxels.data());
    openvdb::tools::copyToDense(*grid, dense);
  }
  v.path = path;
  // The reader is OpenVDB's; the one the volume was first read with (save_vdb's metadata) in brackets.
  v.reader = kVdbReader;
  v.component_type = "float";
  if (const auto r = meta<openvdb::StringMetadata>(*grid, kMetaReader); r && r->value() != kVdbReader)
    v.reader += kConvertedFrom + r->value() + ")";
  if (const auto c = meta<openvdb::StringMetadata>(*grid, kMetaComponent)) v.component_type = c->value();
  v.update_stats();

  if (const auto s = meta<openvdb::StringMetadata>(*grid, kMetaSource)) out.source_path = s->value();
  const auto tau = meta<openvdb::DoubleMetadata>(*grid, kMetaIso);
  const auto inside = meta<openvdb::StringMetadata>(*grid, kMetaInside);
  if (tau && inside && (inside->value() == "above" || inside->value() == "below"))
    out.suggested = core::Isosurface{tau->value(), inside->value() == "above" ? core::InsideIs::kAbove : core::InsideIs::kBelow};
  else if (grid->getGridClass() == openvdb::GRID_LEVEL_SET)
    out.suggested = core::Isosurface{0.0, core::InsideIs::kBelow};
#else
  (void)grid_name;
  (void)max_voxels;
#endif
  return out;
}

// ---------------------------------------------------------------------------------------
// .vdb out

void save_vdb(const engine::Volume& vol, const std::string& path, const SaveVdbOptions& opt) {
  require_openvdb(path);
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VdbError(path + ": cannot save an empty volume or one whose voxel count does not match its dims");
#ifdef ISOTOUCH_HAVE_OPENVDB
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (float x : vol.voxels)
    if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
  if (!(lo <= hi)) lo = hi = 0.0f;
  const float background = opt.iso ? float(opt.iso->outside_value(lo, hi)) : lo;
  FloatGrid::Ptr grid = dense_to_grid(vol, background, [](float x) { return x; });
  grid->setName(opt.grid_name);
  const auto& g = vol.grid;
  try {
    auto map = std::make_shared<openvdb::math::ScaleTranslateMap>(
        openvdb::Vec3d(g.spacing_m.x, g.spacing_m.y, g.spacing_m.z), openvdb::Vec3d(g.origin_m.x, g.origin_m.y, g.origin_m.z));
    grid->setTransform(std::make_shared<openvdb::math::Transform>(map));
  } catch (const openvdb::Exception& e) {  // OpenVDB refuses a voxel volume below 3e-15 (world units^3)
    std::ostringstream m;
    m << path << ": OpenVDB refuses the transform (spacing " << g.spacing_m.x << ", " << g.spacing_m.y << ", "
      << g.spacing_m.z << " m): " << e.what();
    throw VdbError(m.str());
  }
  grid->setGridClass(openvdb::GRID_UNKNOWN);
  grid->setSaveFloatAsHalf(false);
  if (opt.iso) {
    grid->insertMeta(kMetaIso, openvdb::DoubleMetadata(opt.iso->tau));
    grid->insertMeta(kMetaInside, openvdb::StringMetadata(core::to_string(opt.iso->inside)));
  }
  grid->insertMeta(kMetaSource, openvdb::StringMetadata(opt.source_path.empty() ? vol.path : opt.source_path));
  grid->insertMeta(kMetaBoxMin, openvdb::Vec3IMetadata(openvdb::Vec3i(0, 0, 0)));
  grid->insertMeta(kMetaDims, openvdb::Vec3IMetadata(openvdb::Vec3i(g.dims[0], g.dims[1], g.dims[2])));
  openvdb::Mat4d d = openvdb::Mat4d::identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) d(r, c) = vol.direction[std::size_t(3 * r + c)];
  grid->insertMeta(kMetaDirection, openvdb::Mat4DMetadata(d));
  grid->insertMeta(kMetaUnits, openvdb::StringMetadata("m"));
  grid->insertMeta(kMetaSpacing, openvdb::Vec3DMetadata(openvdb::Vec3d(g.spacing_m.x, g.spacing_m.y, g.spacing_m.z)));
  grid->insertMeta(kMetaOrigin, openvdb::Vec3DMetadata(openvdb::Vec3d(g.origin_m.x, g.origin_m.y, g.origin_m.z)));
  grid->insertMeta(kMetaReader, openvdb::StringMetadata(first_reader(vol.reader)));
  grid->insertMeta(kMetaComponent, openvdb::StringMetadata(vol.component_type));
  write_atomically(path, [&](const std::string& tmp) {
    try {
      openvdb::io::File file(tmp);
      file.write(openvdb::GridCPtrVec{grid});
    } catch (const openvdb::Exception& e) {
      throw VdbError(tmp + ": OpenVDB write failed: " + e.what());
    }
  });
#else
  (void)opt;
#endif
}

// ---------------------------------------------------------------------------------------
// Meshes

Mesh extract_mesh(const engine::Volume& vol, const core::Isosurface& iso, double adaptivity) {
  require_openvdb(vol.path);
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VdbError(vol.path + ": cannot mesh an empty volume");
  if (!(adaptivity >= 0.0 && adaptivity <= 1.0))
    throw VdbError("adaptivity must be in [0, 1], got " + std::to_string(adaptivity));
  Mesh mesh;
#ifdef ISOTOUCH_HAVE_OPENVDB
  // OpenVDB meshes {value < iso} as the inside; inside "above" is meshed as -value < -tau.
  const float sign = iso.inside == core::InsideIs::kAbove ? -1.0f : 1.0f;
  const float tau = sign * float(iso.tau);
  float hi = tau;  // outside value: above every (mapped) voxel and strictly above tau
  for (float x : vol.voxels)
    if (std::isfinite(x)) hi = std::max(hi, sign * x);
  const float outside = hi > tau ? hi : std::nextafter(tau, std::numeric_limits<float>::infinity());
  FloatGrid::Ptr grid = dense_to_grid(
      vol, outside, [&](float x) { return std::isnan(x) ? outside : sign * x; }, tau);
  std::vector<openvdb::Vec3s> pts;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, pts, tris, quads, double(tau), adaptivity);
  // Points come in index space (identity transform): index -> grid-world -> physical.
  // Points at one position are welded into one vertex (first one kept).
  std::vector<std::uint32_t> remap(pts.size());
  {
    std::map<std::array<float, 3>, std::uint32_t> at;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const std::array<float, 3> key{pts[i][0], pts[i][1], pts[i][2]};
      const auto [it, fresh] = at.emplace(key, std::uint32_t(mesh.vertices.size()));
      remap[i] = it->second;
      if (!fresh) {
        ++mesh.welded_vertices;
        continue;
      }
      const auto& g = vol.grid;
      mesh.vertices.push_back(to_physical(vol, g.origin_m.x + double(key[0]) * g.spacing_m.x,
                                          g.origin_m.y + double(key[1]) * g.spacing_m.y,
                                          g.origin_m.z + double(key[2]) * g.spacing_m.z));
    }
  }
  // OpenVDB winds its polygons counter-clockwise seen from outside (the side of values
  // >= iso, here always the outside); reversed where D mirrors space (det D = -1).
  const bool mirror = det3(vol.direction) < 0.0;
  auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    a = remap[a];
    b = remap[b];
    c = remap[c];
    if (a == b || b == c || a == c) {  // two corners welded: zero area
      ++mesh.dropped_triangles;
      return;
    }
    if (mirror) mesh.triangles.push_back({a, c, b});
    else mesh.triangles.push_back({a, b, c});
  };
  mesh.triangles.reserve(tris.size() + 2 * quads.size());
  for (const auto& t : tris) add(t[0], t[1], t[2]);
  for (const auto& q : quads) {
    add(q[0], q[1], q[2]);
    add(q[0], q[2], q[3]);
  }
#else
  (void)iso;
  (void)adaptivity;
#endif
  return mesh;
}

MeshStats mesh_stats(const Mesh& m) {
  MeshStats s;
  s.triangles = m.triangles.size();
  s.vertices = m.vertices.size();
  if (!m.vertices.empty()) {
    s.min = s.max = m.vertices[0];
    for (const auto& v : m.vertices)
      for (int a = 0; a < 3; ++a) s.min[a] = std::min(s.min[a], v[a]), s.max[a] = std::max(s.max[a], v[a]);
  }
  std::unordered_map<std::uint64_t, std::uint32_t> edge_use;
  edge_use.reserve(m.triangles.size() * 2);
  for (const auto& t : m.triangles) {
    const auto& a = m.vertices[t[0]];
    const auto& b = m.vertices[t[1]];
    const auto& c = m.vertices[t[2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    s.area_m2 += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    // Signed volume of the tetrahedron (0, a, b, c): a . (b x c) / 6.
    s.signed_volume_m3 += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                           a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) ++s.degenerate_triangles;
    for (int e = 0; e < 3; ++e) {
      const std::uint64_t p = t[std::size_t(e)], q = t[std::size_t((e + 1) % 3)];
      ++edge_use[std::min(p, q) << 32 | std::max(p, q)];
    }
  }
  s.edges = edge_use.size();
  for (const auto& [e, n] : edge_use) {
    if (n == 1) ++s.boundary_edges;
    if (n >= 3) ++s.nonmanifold_edges;
  }
  return s;
}

bool volume_writable(const std::string& path) { return lower_extension(path) == ".vdb" || itk_writable(path); }

void save_any_volume(const engine::Volume& volume, const std::string& path, const SaveVdbOptions& options) {
  if (lower_extension(path) == ".vdb") return save_vdb(volume, path, options);
  if (!itk_writable(path))
    throw VdbError(path + ": unknown volume format: the name must end in .vdb (OpenVDB), .mha (MetaImage), .nrrd "
                          "(NRRD), .nii or .nii.gz (NIfTI)" +
                   (lower_extension(path) == ".mhd" ? std::string(" (.mhd writes a second .raw file that cannot be "
                                                                  "replaced atomically: use .mha)")
                                                    : std::string()));
  try {
    save_volume_itk(volume, path);
  } catch (const engine::VolumeError& e) {
    throw VdbError(e.what());
  }
}

// ---------------------------------------------------------------------------------------
// Test files

void write_test_vdb(const std::string& path, TestVdb kind) {
  require_openvdb(path);
#ifdef ISOTOUCH_HAVE_OPENVDB
  openvdb::initialize();
  openvdb::GridPtrVec grids;
  switch (kind) {
    case TestVdb::kLevelSetSphere: {
      auto g = openvdb::tools::createLevelSetSphere<FloatGrid>(20.0f * 1e-3f, openvdb::Vec3f(0, 0, 0), 1e-3f, 3.0f);
      g->setName("sphere");
      grids.push_back(g);
      break;
    }
    case TestVdb::kNoFloatGrid: {
      auto a = openvdb::Int32Grid::create(0);
      a->setName("labels");
      a->tree().setValue(Coord(1, 2, 3), 7);
      auto b = openvdb::Vec3SGrid::create();
      b->setName("velocity");
      b->tree().setValue(Coord(0, 0, 0), openvdb::Vec3s(1, 0, 0));
      grids = {a, b};
      break;
    }
    case TestVdb::kEmptyFloatGrid: {
      auto g = FloatGrid::create(1.0f);
      g->setName("empty");
      grids.push_back(g);
      break;
    }
    case TestVdb::kHugeBox: {
      auto g = FloatGrid::create(0.0f);
      g->setName("far");
      g->tree().setValue(Coord(0, 0, 0), 1.0f);
      g->tree().setValue(Coord(100000, 100000, 100000), 1.0f);
      grids.push_back(g);
      break;
    }
    case TestVdb::kWrappingBox: {
      // Active corners whose loaded box (margin 1, 8-aligned) spans 2^31 x 2^17 x 2^16 voxels:
      // int32 extents wrap, and their product as uint64 is 0 mod 2^64.
      auto g = FloatGrid::create(0.0f);
      g->setName("wrap");
      g->tree().setValue(Coord(-(1 << 30) + 1, 1, 1), 1.0f);
      g->tree().setValue(Coord((1 << 30) - 2, (1 << 17) - 2, (1 << 16) - 2), 1.0f);
      grids.push_back(g);
      break;
    }
    case TestVdb::kTileBox: {
      auto g = FloatGrid::create(0.0f);
      g->setName("tiles");
      g->fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(1919, 1023, 1023)), 1.0f, /*active=*/true);
      g->setTransform(openvdb::math::Transform::createLinearTransform(1e-3));
      grids.push_back(g);
      break;
    }
    case TestVdb::kRotated: {
      auto g = FloatGrid::create(0.0f);
      g->setName("rotated");
      g->tree().setValue(Coord(0, 0, 0), 1.0f);
      openvdb::math::Transform::Ptr t = openvdb::math::Transform::createLinearTransform(1e-3);
      t->postRotate(M_PI / 6, openvdb::math::Z_AXIS);
      g->setTransform(t);
      grids.push_back(g);
      break;
    }
  }
  openvdb::io::File(path).write(grids);
#else
  (void)kind;
#endif
}

engine::Volume load_any_volume(const std::string& path) {
  if (lower_extension(path) == ".vdb") return load_vdb(path).volume;
  return io::load_volume(path);
}

}  // namespace isotouch::io
