// export.cpp - what `isotouch export` runs; see export.h.
#include "isotouch/run/export.h"
#include "isotouch/io/volume_write.h"

#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <iostream>
#include <memory>

#include "isotouch/io/scene.h"
#include "isotouch/eval/shapes.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/scan.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::run {
using io::extract_mesh;
using io::load_scene;
using io::load_vdb;
using io::mesh_stats;
using io::save_vdb;
using io::LoadedVdb;
using io::Mesh;
using io::MeshStats;
using io::SaveVdbOptions;
using io::Scene;
using io::write_obj;
using io::write_ply;
using io::write_stl_binary;
namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Input {
  engine::Volume volume;
  std::optional<core::Isosurface> iso;  ///< from the scene or the .vdb
  std::string iso_source;               ///< where iso came from
};

/// A volume that gives no isosurface of its own: the one it opens at (engine::choose_isovalue), with its rule.
void choose_isosurface(Input& in, const engine::IsoChoice& c) {
  in.iso = c.iso;
  in.iso_source = "chosen by " + c.rule;
}

Input load_input(const ExportOptions& o, std::ostream& err) {
  Input in;
  if (!o.scene.empty()) {
    const Scene scene = load_scene(o.scene);
    in.iso = core::Isosurface{scene.hri.tau, scene.hri.inside};
    in.iso_source = "scene " + o.scene;
    if (!scene.volume_path.empty()) {
      err << "export: loading " << scene.volume_path << " (scene " << o.scene << ")\n";
      if (ends_with(scene.volume_path, ".vdb")) in.volume = load_vdb(scene.volume_path, o.grid).volume;
      else in.volume = io::load_volume(scene.volume_path);
    } else if (scene.synthetic.kind == "sphere") {
      in.volume = engine::make_sphere(scene.synthetic.dims, scene.synthetic.spacing_m, scene.synthetic.radius_vox);
    } else {
      in.volume = std::move(eval::make_synthetic_scene(scene.synthetic.kind).volume);
    }
    return in;
  }
  err << "export: loading " << o.volume << "\n";
  if (ends_with(o.volume, ".vdb")) {
    LoadedVdb l = load_vdb(o.volume, o.grid);
    err << "export: grid '" << l.grid_name << "' (" << l.grid_class << "), background " << l.background << "\n";
    in.volume = std::move(l.volume);
    in.iso = l.suggested;
    in.iso_source = io::suggested_source(l);
    if (!in.iso) choose_isosurface(in, engine::choose_isovalue(in.volume, engine::VolumeHints{}));
  } else {
    io::Scan scan = io::load_scan(o.volume);
    const engine::IsoChoice c = io::choose_isovalue(scan);
    in.volume = std::move(scan.volume);
    choose_isosurface(in, c);
  }
  return in;
}

/// The mesh's figures; its bounds in the files' unit `u`, so they read as the files do.
void print_mesh(const MeshStats& s, io::MeshUnits u, std::ostream& out) {
  const double k = io::units_per_metre(u);
  char line[512];
  std::snprintf(line, sizeof line,
                "mesh        %zu triangles, %zu vertices\n"
                "area        %.6g m^2 (%.6g cm^2)\n"
                "volume      %.6g m^3 (%.6g cm^3) enclosed, signed (> 0: normals point out)\n"
                "bounds      [%.6g, %.6g] x [%.6g, %.6g] x [%.6g, %.6g] %s (physical frame, LPS, as in the files)\n",
                s.triangles, s.vertices, s.area_m2, s.area_m2 * 1e4, s.signed_volume_m3, s.signed_volume_m3 * 1e6,
                s.min[0] * k, s.max[0] * k, s.min[1] * k, s.max[1] * k, s.min[2] * k, s.max[2] * k, io::to_string(u));
  out << line;
  if (s.closed())
    out << "closed      yes (each of " << s.edges << " edges in exactly 2 triangles)\n";
  else
    out << "closed      NO: " << s.boundary_edges << " edges in 1 triangle, " << s.nonmanifold_edges
        << " edges in 3 or more (of " << s.edges << ")\n";
}

/// "(N bytes, S s)" for a regular file; a device, FIFO or "-" has no size to report.
std::string written_text(const std::string& path, double seconds) {
  std::error_code ec;
  const bool regular = path != "-" && std::filesystem::is_regular_file(path, ec);
  std::ostringstream s;
  if (regular) s << "(" << std::filesystem::file_size(path, ec) << " bytes, " << seconds << " s)";
  else s << "(written as a stream, " << seconds << " s)";
  return s.str();
}

/// True for an output written as a stream whatever its name: "-", or an existing FIFO or device.
bool stream_output(const std::string& path) {
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  return path == "-" || (!ec && std::filesystem::exists(st) && !std::filesystem::is_regular_file(st) &&
                         !std::filesystem::is_directory(st));
}

/// Each output's name must ask for the format its option writes (a stream excepted): "" or
/// the line saying which does not.
std::string misnamed_output(const ExportOptions& o) {
  const std::pair<const char*, const std::string*> outputs[] = {
      {"vdb", &o.vdb}, {"stl", &o.stl}, {"obj", &o.obj}, {"ply", &o.ply}};
  for (const auto& [format, path] : outputs) {
    if (path->empty() || stream_output(*path)) continue;
    std::string ext = std::filesystem::path(*path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    const std::string asked = std::string(format) == "vdb" ? (ext == ".vdb" ? "vdb" : "") : io::mesh_format(*path);
    if (asked == format) continue;
    std::string m = std::string("--") + format + " " + *path + ": the name must end in ." + format;
    if (!io::mesh_format(*path).empty()) m += " (--" + io::mesh_format(*path) + " writes ." + io::mesh_format(*path) + ")";
    else if (io::itk_writable(*path)) m += " (--volume writes it)";
    return m + "; nothing was written";
  }
  return "";
}

}  // namespace

int run_export(const ExportOptions& o, std::ostream& out_stream, std::ostream& err) {
  // An output to standard output ("-") takes stdout for its bytes: the figures go to stderr.
  const int to_stdout =
      int(o.vdb == "-") + int(o.stl == "-") + int(o.obj == "-") + int(o.ply == "-") + int(o.volume_out == "-");
  if (to_stdout > 1) {
    err << "isotouch export: only one output can be '-' (standard output)\n";
    return 2;
  }
  std::ostream& out = to_stdout ? err : out_stream;
  if (o.volume.empty() == o.scene.empty()) {
    err << "isotouch export: give a VOLUME file or --scene SCENE, one of them (see --help)\n";
    return 2;
  }
  const bool mesh_wanted = !o.stl.empty() || !o.obj.empty() || !o.ply.empty();
  if (!mesh_wanted && o.vdb.empty() && o.volume_out.empty()) {
    err << "isotouch export: nothing to write: give --vdb, --volume, --stl, --obj and/or --ply\n";
    return 2;
  }
  if (o.volume_out == "-") {
    err << "isotouch export: --volume -: ITK's writers take the format from the file name; give a name ending in "
           ".mha, .nrrd, .nii or .nii.gz (a FIFO or device named so is written as a stream)\n";
    return 2;
  }
  if (!o.volume_out.empty() && !io::itk_writable(o.volume_out)) {
    err << "isotouch export: --volume " << o.volume_out
        << ": the name must end in .mha (MetaImage), .nrrd (NRRD), .nii or .nii.gz (NIfTI)"
        << (o.volume_out.size() > 4 && o.volume_out.substr(o.volume_out.size() - 4) == ".mhd"
                ? " (.mhd writes a second .raw file that cannot be replaced atomically: use .mha)"
                : "")
        << "\n";
    return 2;
  }
  if (const std::string m = misnamed_output(o); !m.empty()) {
    err << "isotouch export: " << m << "\n";
    return 2;
  }
  if (!o.inside.empty() && o.inside != "above" && o.inside != "below") {
    err << "isotouch export: --inside must be 'above' or 'below', got '" << o.inside << "'\n";
    return 2;
  }
  const auto t0 = std::chrono::steady_clock::now();
  Input in = load_input(o, err);
  const engine::Volume& v = in.volume;
  err << "export: " << v.grid.dims[0] << " x " << v.grid.dims[1] << " x " << v.grid.dims[2] << " voxels loaded in "
      << seconds_since(t0) << " s\n";

  // The isosurface: --iso / --inside over the scene's or the .vdb's.
  std::optional<core::Isosurface> iso = in.iso;
  std::string iso_source = in.iso_source;
  if (o.iso || !o.inside.empty()) {
    if (!iso && (!o.iso || o.inside.empty())) {
      err << "isotouch export: give both --iso TAU and --inside above|below (the input suggests no isosurface)\n";
      return 2;
    }
    core::Isosurface i = iso.value_or(core::Isosurface{});
    if (o.iso) i.tau = *o.iso;
    if (!o.inside.empty()) i.inside = o.inside == "above" ? core::InsideIs::kAbove : core::InsideIs::kBelow;
    iso = i;
    iso_source = "command line";
  }
  if (mesh_wanted && !iso) {
    err << "isotouch export: no isosurface for the mesh: give --iso TAU --inside above|below "
           "(CT densities: above; signed distances: below)\n";
    return 2;
  }
  if (iso) out << "isosurface  tau " << iso->tau << ", inside " << core::to_string(iso->inside) << " (" << iso_source << ")\n";

  if (!o.vdb.empty()) {
    const auto t = std::chrono::steady_clock::now();
    err << "export: writing " << o.vdb << "\n";
    save_vdb(v, o.vdb, SaveVdbOptions{.grid_name = "volume", .iso = iso, .source_path = v.path});
    out << "wrote       " << o.vdb << " " << written_text(o.vdb, seconds_since(t)) << "\n";
  }
  if (!o.volume_out.empty()) {
    const auto t = std::chrono::steady_clock::now();
    err << "export: writing " << o.volume_out << "\n";
    io::save_volume_itk(v, o.volume_out);
    out << "wrote       " << o.volume_out << " " << written_text(o.volume_out, seconds_since(t)) << "\n";
  }
  if (!mesh_wanted) return 0;

  const auto tm = std::chrono::steady_clock::now();
  err << "export: meshing (OpenVDB volumeToMesh, adaptivity " << o.adaptivity << ")\n";
  const Mesh mesh = extract_mesh(v, *iso, o.adaptivity);
  err << "export: meshed in " << seconds_since(tm) << " s\n";
  const MeshStats st = mesh_stats(mesh);
  print_mesh(st, o.mesh_units, out);
  if (mesh.welded_vertices || mesh.dropped_triangles)
    out << "cleaned     " << mesh.welded_vertices << " coincident vertices welded, " << mesh.dropped_triangles
        << " zero-area triangles dropped\n";
  if (mesh.triangles.empty()) {
    err << "isotouch export: the isosurface tau " << iso->tau << " (inside " << core::to_string(iso->inside)
        << ") does not cross the volume (values " << v.min_value << " to " << v.max_value << "): no mesh written\n";
    return 2;
  }
  const std::pair<const std::string*, void (*)(const Mesh&, const std::string&, io::MeshUnits)> writers[] = {
      {&o.stl, write_stl_binary}, {&o.obj, write_obj}, {&o.ply, write_ply}};
  for (const auto& [path, write] : writers) {
    if (path->empty()) continue;
    const auto t = std::chrono::steady_clock::now();
    err << "export: writing " << *path << "\n";
    write(mesh, *path, o.mesh_units);
    out << "wrote       " << *path << " " << written_text(*path, seconds_since(t)) << "\n";
  }
  if (!st.closed()) {
    err << "isotouch export: the mesh is not closed (see above); written anyway\n";
    return 3;
  }
  return 0;
}

}  // namespace isotouch::run
