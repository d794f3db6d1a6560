#include "isotouch/run/volume_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include "isotouch/io/scan.h"

namespace isotouch::run {
namespace fs = std::filesystem;

namespace {
/// Voxels from the face to the first one inside `iso` along the centre line; -1 if none.
int first_inside(const engine::Volume& vol, const core::Isosurface& iso, int axis, int sign) {
  const auto& d = vol.grid.dims;
  std::array<int, 3> p{d[0] / 2, d[1] / 2, d[2] / 2};
  for (int k = 0; k < d[std::size_t(axis)]; ++k) {
    p[std::size_t(axis)] = sign > 0 ? k : d[std::size_t(axis)] - 1 - k;
    const float v = vol.voxels[vol.grid.index(p[0], p[1], p[2])];
    if (std::isfinite(v) && iso.excess(v) > 0) return k;
  }
  return -1;
}

double spacing(const core::Grid& g, int axis) {
  return axis == 0 ? g.spacing_m.x : axis == 1 ? g.spacing_m.y : g.spacing_m.z;
}

std::string vec(const std::array<double, 3>& v) {
  std::ostringstream s;
  s << std::setprecision(17) << "[" << v[0] << ", " << v[1] << ", " << v[2] << "]";
  return s.str();
}

/// A scene name from a file name: letters, digits, '-' and '_' kept, the rest '-'.
std::string scene_name(const std::string& path) {
  std::string stem = fs::path(path).filename().string();
  for (const char* ext : {".nii.gz", ".mhd", ".mha", ".nrrd", ".nhdr", ".nii", ".vdb"})
    if (stem.size() > std::string(ext).size() && stem.ends_with(ext)) {
      stem.resize(stem.size() - std::string(ext).size());
      break;
    }
  for (char& c : stem)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '-';
  return stem.empty() ? "volume" : stem;
}

/// A JSON string literal (quotes, backslashes and control characters escaped).
std::string quoted(const std::string& s) {
  std::ostringstream o;
  o << '"';
  for (char c : s) {
    if (c == '"' || c == '\\') o << '\\' << c;
    else if (static_cast<unsigned char>(c) < 0x20) o << "\\u" << std::hex << std::setw(4) << std::setfill('0') << int(c) << std::dec;
    else o << c;
  }
  return o.str() + '"';
}
}  // namespace

/// The value at the face where the centre line along (axis, sign) enters.
float face_value(const engine::Volume& vol, int axis, int sign) {
  const auto& d = vol.grid.dims;
  std::array<int, 3> p{d[0] / 2, d[1] / 2, d[2] / 2};
  p[std::size_t(axis)] = sign > 0 ? 0 : d[std::size_t(axis)] - 1;
  return vol.voxels[vol.grid.index(p[0], p[1], p[2])];
}

Approach choose_approach(const engine::Volume& vol, const core::Isosurface& iso) {
  // Background: the three-class Otsu class farthest on the outside of the isosurface (air on a
  // CT); a line that enters through anything else enters where the scan was cropped.
  const std::vector<double> t = engine::otsu_thresholds(engine::histogram(vol, 256), 3);
  const auto background = [&](float v) {
    if (t.size() != 2) return iso.excess(v) < 0;
    return iso.inside == core::InsideIs::kAbove ? v < t[0] : v > t[1];
  };
  Approach best;
  // First the lines entering through background; if none does (a smooth field such as a
  // signed distance has no background class at its faces), any with room before the surface.
  for (bool need_background : {true, false}) {
    for (int axis = 0; axis < 3; ++axis)
      for (int sign : {+1, -1}) {
        const int k = first_inside(vol, iso, axis, sign);
        if (k < 2 || (need_background && !background(face_value(vol, axis, sign)))) continue;  // the crop
        const double air = k * spacing(vol.grid, axis);
        if (!best.found || air < best.air_m) best = Approach{axis, sign, air, true};
      }
    if (best.found) break;
  }
  return best;
}

std::string describe_approach(const engine::Volume& vol, const Approach& a) {
  const char axis = char('x' + a.axis);
  const std::string o = vol.orientation();
  // The probe starts on the face the ray leaves from: for sign +1 the low face, on the side
  // opposite the letter the axis points toward.
  static const std::string kLetters = "LRPAIS";  // pairs of opposites
  const char toward = o[std::size_t(a.axis)];
  const char from = a.sign > 0 ? kLetters[kLetters.find(toward) ^ 1u] : toward;
  std::ostringstream s;
  s << std::setprecision(3) << "along " << (a.sign > 0 ? "+" : "-") << axis << " (index) from the " << from
    << " side (orientation " << o << ")";
  if (a.found) s << ", the surface " << a.air_m * 1e3 << " mm inside the box";
  else s << ": no axis through the centre meets the surface off the box's faces";
  return s.str();
}

bool is_volume_path(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return true;
  const std::string ext = io::lower_extension(path);
  return ext == ".mhd" || ext == ".mha" || ext == ".nrrd" || ext == ".nhdr" || ext == ".nii" || ext == ".vdb" ||
         (ext == ".gz" && io::lower_extension(fs::path(path).stem().string()) == ".nii");
}

VolumeScene make_volume_scene(const std::string& volume_path, std::optional<double> iso, const std::string& inside) {
  const io::Scan scan = io::load_scan(volume_path);
  engine::IsoChoice choice;
  if (iso) {
    choice.iso = core::Isosurface{*iso, inside == "below" ? core::InsideIs::kBelow : core::InsideIs::kAbove};
    choice.rule = "hand (--iso)";
  } else {
    choice = io::choose_isovalue(scan);
  }
  return make_volume_scene(scan.volume, choice, volume_path);
}

VolumeScene make_volume_scene(const engine::Volume& volume, const engine::IsoChoice& choice,
                              const std::string& volume_path, const std::string& servo_json) {
  VolumeScene out;
  out.choice = choice;
  out.approach = choose_approach(volume, out.choice.iso);
  out.approach_text = describe_approach(volume, out.approach);
  const Approach& a = out.approach;
  // The ray runs along the index line through the centre voxel that choose_approach looked
  // along (its fraction of the box, not the box's centre half a voxel beside it: a thin
  // crossing on that line may be missed beside it).
  const auto& d = volume.grid.dims;
  std::array<double, 3> origin{}, dir{0, 0, 0}, stroke{0, 0, 0};
  for (std::size_t k = 0; k < 3; ++k) origin[k] = d[k] > 1 ? double(d[k] / 2) / double(d[k] - 1) : 0.5;
  origin[std::size_t(a.axis)] = a.sign > 0 ? -0.2 : 1.2;
  dir[std::size_t(a.axis)] = a.sign;
  const int s_axis = (a.axis + 1) % 3;
  stroke[std::size_t(s_axis)] = 1;
  const auto& g = volume.grid;
  const double box = (g.dims[std::size_t(s_axis)] - 1) * spacing(g, s_axis);
  const double stroke_m = std::min(0.04, std::max(0.25 * box, 1e-3));
  std::ostringstream j;
  j << std::setprecision(17) << "{\n  \"name\": " << quoted(scene_name(volume_path)) << ",\n  \"description\": "
    << quoted("Made by isotouch run for " + volume_path + ": " + engine::iso_line(out.choice) +
              "; the probe approaches " + out.approach_text + ", presses along the surface normal and strokes on the surface from +" +
              char('x' + s_axis) + " (planned on the true isosurface: script.plan). Edit and run it as a scene.")
    << ",\n  \"volume\": {\"path\": " << quoted(is_in_memory_name(volume_path) ? volume_path : fs::absolute(volume_path).lexically_normal().string())
    << "},\n  \"isovalue\": " << out.choice.iso.tau << ",\n  \"inside\": \"" << core::to_string(out.choice.iso.inside)
    << "\",\n" << (servo_json.empty() ? "" : "  \"servo\": " + servo_json + ",\n") << "  \"script\": {\n    \"ray_origin_frac\": " << vec(origin) << ",\n    \"ray_direction\": " << vec(dir)
    << ",\n    \"stroke_direction\": " << vec(stroke) << ",\n    \"stroke_length_m\": " << stroke_m << ",\n    \"plan\": \"surface\"\n  }\n}\n";
  out.json = j.str();
  out.scene = io::parse_scene(out.json, volume_path + " (the scene made for it)");
  return out;
}

}  // namespace isotouch::run
