#include "isotouch/io/scene.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "isotouch/io/scene_fields.h"
#include "isotouch/sim/stability.h"

namespace isotouch::io {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

class Reader {
 public:
  explicit Reader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const std::string& field, const std::string& what) const {
    throw SceneError(file_ + ": field '" + field + "': " + what);
  }

  void only(const json& obj, const std::string& where, std::set<std::string> allowed) const {
    if (!obj.is_object()) fail(where, "must be an object, got " + obj.dump());
    for (auto it = obj.begin(); it != obj.end(); ++it)
      if (!allowed.count(it.key())) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail(where.empty() ? it.key() : where + "." + it.key(), "unknown field (allowed: " + list + ")");
      }
  }

  // A number at obj[key], checked against the range kSceneFields gives `section`.`key`
  // (`section` "" = `where`); absent, `fallback` when given, else the table's default.
  double number(const json& obj, const std::string& where, const std::string& key,
                std::optional<double> fallback = {}, std::string_view section = {}) const {
    const SceneField& fld = table_field(section.empty() ? where : section, key);
    if (!obj.contains(key)) return absent(fld, fallback);
    const json& v = obj.at(key);
    if (!v.is_number()) fail(name(where, key), "must be a number, got " + v.dump());
    return in_range(fld, v, where);
  }

  // As number(), for a field whose range says "integer".
  int integer(const json& obj, const std::string& where, const std::string& key,
              std::optional<double> fallback = {}, std::string_view section = {}) const {
    const SceneField& fld = table_field(section.empty() ? where : section, key);
    if (!obj.contains(key)) return int(absent(fld, fallback));
    const json& v = obj.at(key);
    if (!v.is_number_integer()) fail(name(where, key), "must be an integer, got " + v.dump());
    return int(in_range(fld, v, where));
  }

  core::Vec3 vec3(const json& obj, const std::string& where, const std::string& key,
                   core::Vec3 def) const {
    const std::string f = where + "." + key;
    if (!obj.contains(key)) return def;
    const json& v = obj.at(key);
    if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() || !v[2].is_number())
      fail(f, "must be an array of 3 numbers, got " + v.dump());
    core::Vec3 r{v[0].get<double>(), v[1].get<double>(), v[2].get<double>()};
    if (!core::finite(r) || std::abs(r.x) > 1e6 || std::abs(r.y) > 1e6 || std::abs(r.z) > 1e6)
      fail(f, "must be finite and of sane size, got " + v.dump());
    return r;
  }

  std::string string(const json& obj, const std::string& where, const std::string& key,
                     const std::string& def) const {
    const std::string f = where.empty() ? key : where + "." + key;
    if (!obj.contains(key)) return def;
    if (!obj.at(key).is_string()) fail(f, "must be a string, got " + obj.at(key).dump());
    return obj.at(key).get<std::string>();
  }

  bool boolean(const json& obj, const std::string& where, const std::string& key, bool def) const {
    if (!obj.contains(key)) return def;
    if (!obj.at(key).is_boolean()) fail(where + "." + key, "must be true or false, got " + obj.at(key).dump());
    return obj.at(key).get<bool>();
  }

  const json& section(const json& root, const std::string& key) const {
    static const json empty = json::object();
    return root.contains(key) ? root.at(key) : empty;
  }

 private:
  static std::string name(const std::string& where, const std::string& key) {
    return where.empty() ? key : where + "." + key;
  }

  // Every number the parser reads has a row with a numeric range: a missing one is a bug here.
  static const SceneField& table_field(std::string_view section, const std::string& key) {
    const SceneField* f = scene_field(section, key);
    if (!f || !field_range(f->range))
      throw std::logic_error("io/scene_fields.h: no numeric field '" + key + "' in section '" + std::string(section) + "'");
    return *f;
  }

  // The caller's fallback (a default that depends on other fields) or the table's.
  static double absent(const SceneField& f, std::optional<double> fallback) {
    if (fallback) return *fallback;
    if (const auto d = plain_number(f.default_text)) return *d;
    throw std::logic_error("io/scene_fields.h: '" + std::string(f.key) + "' has no numeric default");
  }

  // The value `v` (a JSON number) if it lies in the table's range for `f`; else the error
  // naming the file, the field and the value.
  double in_range(const SceneField& f, const json& v, const std::string& where) const {
    const FieldRange range = *field_range(f.range);
    const double d = v.get<double>();
    if (!range.contains(d)) fail(name(where, std::string(f.key)), "must be " + range.phrase() + ", got " + v.dump());
    return d;
  }

  std::string file_;
};

// "engine": {"passes": [{"gaussian": {"sigma_mm": 1}}, {"closing": {"radius_mm": 1}}, "gradient"],
//            "mode": "sparse" | "dense", "samples": "fp32" | "fp16" | "unorm16"}
// A pass is its name (a string) or an object with one key, the name, holding its parameters.
// Ranges here name the field; the list's structure is checked again by engine::validate_passes
// (run::scene_passes) before anything runs.
PassSpec parse_pass(const Reader& r, const json& p, std::size_t i) {
  const std::string where = "engine.passes[" + std::to_string(i) + "]";
  static const char* kKinds = "\"gaussian\", \"closing\", \"gradient\", \"brick_minmax\"";
  PassSpec ps;
  json params = json::object();
  if (p.is_string()) {
    ps.kind = p.get<std::string>();
  } else if (p.is_object() && p.size() == 1) {
    ps.kind = p.begin().key();
    params = p.begin().value();
  } else {
    r.fail(where, std::string("must be a pass name or {\"name\": {parameters}} with one name (") + kKinds + "), got " +
                      p.dump());
  }
  const std::string at = where + "." + ps.kind;
  if (ps.kind == "gaussian") {
    r.only(params, at, scene_keys("engine.passes.gaussian"));
    if (!params.contains("sigma_mm")) r.fail(at + ".sigma_mm", "is required (the Gaussian's standard deviation in mm)");
    ps.sigma_mm = r.number(params, at, "sigma_mm", {}, "engine.passes.gaussian");
  } else if (ps.kind == "closing") {
    r.only(params, at, scene_keys("engine.passes.closing"));
    if (!params.contains("radius_mm")) r.fail(at + ".radius_mm", "is required (the box half-width in mm)");
    ps.radius_mm = r.number(params, at, "radius_mm", {}, "engine.passes.closing");
  } else if (ps.kind == "gradient") {
    if (!params.is_object() || !params.empty()) r.fail(at, "takes no parameters, got " + params.dump());
  } else if (ps.kind == "brick_minmax") {
    r.only(params, at, scene_keys("engine.passes.brick_minmax"));
    ps.halo = r.integer(params, at, "halo", {}, "engine.passes.brick_minmax");
  } else {
    r.fail(where, "unknown pass \"" + ps.kind + "\" (known: " + kKinds + ")");
  }
  return ps;
}

void parse_engine(const Reader& r, const json& e, EngineSpec& spec) {
  r.only(e, "engine", scene_keys("engine"));
  if (e.contains("passes")) {
    const json& list = e.at("passes");
    if (!list.is_array() || list.empty())
      r.fail("engine.passes", "must be a non-empty array of passes, got " + list.dump());
    spec.passes.clear();
    for (std::size_t i = 0; i < list.size(); ++i) spec.passes.push_back(parse_pass(r, list[i], i));
    std::size_t gradient = spec.passes.size();
    for (std::size_t i = 0; i < spec.passes.size(); ++i)
      if (spec.passes[i].kind == "gradient" && gradient == spec.passes.size()) gradient = i;
    if (gradient == spec.passes.size())
      r.fail("engine.passes", "must include \"gradient\" (the servo reads its samples), got " + list.dump());
    for (std::size_t i = gradient + 1; i < spec.passes.size(); ++i)
      if (spec.passes[i].kind == "gaussian" || spec.passes[i].kind == "closing")
        r.fail("engine.passes[" + std::to_string(i) + "]",
               "a filter after \"gradient\" would change nothing the servo reads; list it before, got " +
                   list[i].dump());
  }
  spec.mode = r.string(e, "engine", "mode", spec.mode);
  if (spec.mode != "sparse" && spec.mode != "dense")
    r.fail("engine.mode", "must be \"sparse\" (bricks near the isosurface) or \"dense\" (every voxel), got \"" +
                              spec.mode + "\"");
  spec.samples = r.string(e, "engine", "samples", spec.samples);
  if (spec.samples != "fp32" && spec.samples != "fp16" && spec.samples != "unorm16")
    r.fail("engine.samples", "must be \"fp32\" (16 B per sample), \"fp16\" or \"unorm16\" (8 B), got \"" +
                                 spec.samples + "\"");
  if (spec.samples != "fp32" && spec.mode == "dense")
    r.fail("engine.samples", "compact samples are stored in bricks: \"" + spec.samples +
                                 "\" needs \"mode\": \"sparse\" (dense snapshots are fp32)");
}

// A brush object: "kind", "radius_mm", "strength", "falloff", "force_threshold_n", "rate"
// or "removal_per_n_s", "density_scale", "material", "empty" (+ "force_n" on the timeline),
// each over `base`.
constexpr std::string_view kBrush = "edits.brush";
const std::set<std::string> kBrushKeys = scene_keys(kBrush);

BrushSpec parse_brush(const Reader& r, const json& b, const std::string& where, BrushSpec base, bool timed) {
  BrushSpec s = base;
  // A timed brush inherits edits.brush's values; edits.brush itself takes the table's defaults.
  const auto inherited = [timed](double v) { return timed ? std::optional<double>(v) : std::nullopt; };
  s.kind = r.string(b, where, "kind", s.kind);
  if (s.kind != "add" && s.kind != "carve" && s.kind != "smooth" && s.kind != "drill")
    r.fail(where + ".kind", "must be \"add\", \"carve\", \"smooth\" or \"drill\"" +
                                std::string(timed ? " (or \"undo\", \"redo\")" : "") + ", got \"" + s.kind + "\"");
  s.radius_mm = r.number(b, where, "radius_mm", inherited(s.radius_mm), kBrush);
  s.strength = r.number(b, where, "strength", inherited(s.strength), kBrush);
  if (s.kind == "smooth" && s.strength > 1)
    r.fail(where + ".strength", "a smooth brush's strength is a fraction in [0, 1], got " +
                                    (b.contains("strength") ? b.at("strength").dump() : std::to_string(s.strength)));
  s.falloff = r.number(b, where, "falloff", inherited(s.falloff), kBrush);
  s.force_threshold_n = r.number(b, where, "force_threshold_n", inherited(s.force_threshold_n), kBrush);
  if (b.contains("rate") && b.contains("removal_per_n_s"))
    r.fail(where + ".removal_per_n_s", "give the drill's rate once: \"rate\" (value units per N s) or "
                                       "\"removal_per_n_s\" (fraction of |material - empty| per N s), not both");
  s.rate = r.number(b, where, "rate", inherited(s.rate), kBrush);
  if (b.contains("rate")) s.removal_per_n_s = -1;
  if (b.contains("removal_per_n_s")) s.removal_per_n_s = r.number(b, where, "removal_per_n_s", {}, kBrush);
  if (b.contains("density_scale")) s.density_scale = r.number(b, where, "density_scale", {}, kBrush);
  if (b.contains("material")) {
    s.has_material = true;
    s.material = r.number(b, where, "material", {}, kBrush);
  }
  if (b.contains("empty")) {
    s.has_empty = true;
    s.empty = r.number(b, where, "empty", {}, kBrush);
  }
  if (timed) s.force_n = r.number(b, where, "force_n", s.force_n, "edits.timeline");
  return s;
}

// "edits": {"brush": {...}, "every_ticks": 10, "button": [[t0, t1], ...], "timeline": [...],
//           "history_limit_mib": 256, "write_vdb": true, "write_nrrd": true, "write_stl": true}
void parse_edits(const Reader& r, const json& e, EditsSpec& spec) {
  r.only(e, "edits", scene_keys("edits"));
  spec.present = true;
  if (e.contains("brush")) {
    r.only(e.at("brush"), "edits.brush", kBrushKeys);
    spec.brush = parse_brush(r, e.at("brush"), "edits.brush", spec.brush, false);
  }
  spec.every_ticks = r.integer(e, "edits", "every_ticks");
  spec.history_limit_mib = r.number(e, "edits", "history_limit_mib");
  spec.write_vdb = r.boolean(e, "edits", "write_vdb", spec.write_vdb);
  spec.write_nrrd = r.boolean(e, "edits", "write_nrrd", spec.write_nrrd);
  spec.write_stl = r.boolean(e, "edits", "write_stl", spec.write_stl);
  if (e.contains("button")) {
    const json& list = e.at("button");
    if (!list.is_array()) r.fail("edits.button", "must be an array of [t0, t1] intervals [s], got " + list.dump());
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string f = "edits.button[" + std::to_string(i) + "]";
      const json& iv = list[i];
      if (!iv.is_array() || iv.size() != 2 || !iv[0].is_number() || !iv[1].is_number())
        r.fail(f, "must be [t0, t1] in seconds, got " + iv.dump());
      const double t0 = iv[0].get<double>(), t1 = iv[1].get<double>();
      if (!std::isfinite(t0) || !std::isfinite(t1) || t0 < 0 || t1 <= t0 || t1 > 1e6)
        r.fail(f, "must be [t0, t1] with 0 <= t0 < t1 <= 1e6 s, got " + iv.dump());
      if (!spec.button_down.empty() && t0 < spec.button_down.back()[1])
        r.fail(f, "intervals must be in order and must not overlap, got " + iv.dump() + " after " +
                      list[i - 1].dump());
      spec.button_down.push_back({t0, t1});
    }
  }
  if (e.contains("timeline")) {
    const json& list = e.at("timeline");
    if (!list.is_array()) r.fail("edits.timeline", "must be an array of timed edits, got " + list.dump());
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string f = "edits.timeline[" + std::to_string(i) + "]";
      const json& it = list[i];
      if (!it.is_object()) r.fail(f, "must be an object {\"t_s\": ..., \"kind\": ..., ...}, got " + it.dump());
      TimedEdit te;
      te.index = int(i);
      if (!it.contains("t_s")) r.fail(f + ".t_s", "is required (when the edit is applied, in seconds)");
      te.t_s = r.number(it, f, "t_s", {}, "edits.timeline");
      if (!it.contains("kind")) r.fail(f + ".kind", "is required (\"add\", \"carve\", \"smooth\", \"drill\", \"undo\", \"redo\")");
      te.kind = r.string(it, f, "kind", "");
      if (te.kind == "undo" || te.kind == "redo") {
        r.only(it, f, {"t_s", "kind"});
      } else {
        std::set<std::string> keys = kBrushKeys;
        keys.merge(scene_keys("edits.timeline"));
        r.only(it, f, keys);
        te.brush = parse_brush(r, it, f, spec.brush, true);
        if (!it.contains("at")) r.fail(f + ".at", "is required: [x, y, z] in mm (physical frame, as trace.csv) or \"vhip\"");
        const json& at = it.at("at");
        if (at.is_string()) {
          if (at.get<std::string>() != "vhip")
            r.fail(f + ".at", "must be [x, y, z] in mm or \"vhip\", got " + at.dump());
          te.at_vhip = true;
        } else {
          te.at_m = r.vec3(it, f, "at", {}) * 1e-3;
        }
        te.duration_s = r.number(it, f, "duration_s", {}, "edits.timeline");
      }
      spec.timeline.push_back(te);
    }
    std::stable_sort(spec.timeline.begin(), spec.timeline.end(),
                     [](const TimedEdit& a, const TimedEdit& b) { return a.t_s < b.t_s; });
  }
}

}  // namespace

// A stroke needs a direction, and a run keeps every tick in memory: the script's length at
// the servo rate is bounded (a 3600 s hold at 100 kHz, or a stroke at 1e-9 m/s, would
// otherwise end in an allocation failure naming nothing).
constexpr double kMaxScriptTicks = 2e7;
void check_script_length(const Reader& r, const Scene& s) {
  const sim::ScriptParams& p = s.script;
  if (p.stroke_length_m > 0 && core::norm(p.stroke_direction) == 0.0)
    r.fail("script.stroke_direction", "must not be [0, 0, 0] when script.stroke_length_m is " +
                                          std::to_string(p.stroke_length_m) + " m (> 0)");
  struct Part {
    const char* field;
    double s;
  };
  const Part parts[] = {{"script.rest_s (twice)", 2 * p.rest_s},
                        {"script.approach_distance_m / approach_speed_m_s (twice)",
                         2 * p.approach_distance_m / p.approach_speed_m_s},
                        {"script.press_depth_m / press_speed_m_s (twice)", 2 * p.press_depth_m / p.press_speed_m_s},
                        {"script.hold_s", p.hold_s},
                        {"script.stroke_length_m / stroke_speed_m_s", p.stroke_length_m / p.stroke_speed_m_s}};
  double total = 0;
  const Part* longest = &parts[0];
  for (const Part& q : parts) {
    total += q.s;
    if (q.s > longest->s) longest = &q;
  }
  const double ticks = total * s.hri.rate_hz;
  if (!(ticks <= kMaxScriptTicks)) {
    std::ostringstream m;
    m << "lasts about " << total << " s at servo.rate_hz " << s.hri.rate_hz << " = " << ticks
      << " ticks, more than the " << kMaxScriptTicks << " a run keeps in memory; the longest part is " << longest->field
      << " (" << longest->s << " s)";
    r.fail("script", m.str());
  }
}

namespace {

// nlohmann's message without its "[json.exception.parse_error.101] " id.
std::string without_json_id(const std::string& what) {
  const std::size_t end = what.rfind("] ", what.find(' '));
  return what.rfind("[json.exception.", 0) == 0 && end != std::string::npos ? what.substr(end + 2) : what;
}

// JSON allows a key twice in one object and keeps the last: a scene with two
// "stiffness_n_per_m" would silently use one of them. The parser callback sees every key
// in order, with the objects and arrays it sits in.
json parse_json_once_each(const std::string& text, const std::string& path) {
  struct Frame {
    bool object;
    std::set<std::string> keys;
    std::string key;
  };
  std::vector<Frame> stack;
  const json::parser_callback_t dup_check = [&](int, json::parse_event_t ev, json& parsed) {
    switch (ev) {
      case json::parse_event_t::object_start: stack.push_back({true, {}, {}}); break;
      case json::parse_event_t::array_start: stack.push_back({false, {}, {}}); break;
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        if (!stack.empty()) stack.pop_back();
        break;
      case json::parse_event_t::key:
        if (!stack.empty() && parsed.is_string()) {
          Frame& f = stack.back();
          f.key = parsed.get<std::string>();
          if (!f.keys.insert(f.key).second) {
            std::string field;
            for (const Frame& fr : stack)
              field += fr.object ? (field.empty() ? "" : ".") + fr.key : std::string("[]");
            throw SceneError(path + ": field '" + field +
                             "': appears twice in the same object (JSON would keep only the last; remove one)");
          }
        }
        break;
      default: break;
    }
    return true;
  };
  try {
    return json::parse(text, dup_check);
  } catch (const json::out_of_range& e) {  // 1e999: past the largest double
    throw SceneError(path + ": not valid JSON: " + without_json_id(e.what()) +
                     ": a number must be finite, at most about 1.8e308 in size");
  } catch (const json::exception& e) {
    throw SceneError(path + ": not valid JSON: " + without_json_id(e.what()) +
                     " (look for a missing comma, quote or bracket there)");
  }
}

void parse_name(const Reader& r, const json& root, const std::string& path, Scene& s) {
  s.name = r.string(root, "", "name", fs::path(path).stem().string());
  s.description = r.string(root, "", "description", "");
  if (s.name.empty()) r.fail("name", "must not be empty (it names the output folder out/<name>)");
  for (char c : s.name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_'))
      r.fail("name", "may hold only letters, digits, '-' and '_', got \"" + s.name + "\"");
}

// "volume": {"path": P} (relative to the scene file) or {"synthetic": KIND, ...}.
void parse_volume(const Reader& r, const json& root, const std::string& path, Scene& s) {
  if (!root.contains("volume")) r.fail("volume", "is required");
  const json& vol = root.at("volume");
  r.only(vol, "volume", scene_keys("volume"));
  if (vol.contains("path") == vol.contains("synthetic"))
    r.fail("volume", "needs exactly one of 'path' or 'synthetic'");
  if (vol.contains("path")) {
    const std::string p = r.string(vol, "volume", "path", "");
    if (p.empty()) r.fail("volume.path", "must not be empty");
    const fs::path pp(p);
    s.volume_path = pp.is_absolute() ? p : (fs::path(path).parent_path() / pp).lexically_normal().string();
    return;
  }
  s.synthetic.kind = r.string(vol, "volume", "synthetic", "");
  if (s.synthetic.kind != "sphere" && s.synthetic.kind != "box" && s.synthetic.kind != "three-spheres" &&
      s.synthetic.kind != "knot")
    r.fail("volume.synthetic", "unknown synthetic volume \"" + s.synthetic.kind +
                                   "\" (known: sphere, box, three-spheres, knot)");
  if (s.synthetic.kind != "sphere" && (vol.contains("dims") || vol.contains("spacing_m") || vol.contains("radius_vox")))
    r.fail("volume", "dims, spacing_m and radius_vox apply to the sphere only; \"" + s.synthetic.kind +
                         "\" is the fixed 64^3 scene of the paper");
  if (vol.contains("dims")) {
    const json& d = vol.at("dims");
    if (!d.is_array() || d.size() != 3) r.fail("volume.dims", "must be [x, y, z], got " + d.dump());
    for (int a = 0; a < 3; ++a) {
      if (!d[std::size_t(a)].is_number_integer() || d[std::size_t(a)].get<long long>() < 2 ||
          d[std::size_t(a)].get<long long>() > 1024)
        r.fail("volume.dims", "each must be an integer in [2, 1024], got " + d.dump());
      s.synthetic.dims[std::size_t(a)] = d[std::size_t(a)].get<int>();
    }
  }
  // [1 um, 0.1 m]: beyond it the sphere is too small to touch or too large to script.
  s.synthetic.spacing_m = r.number(vol, "volume", "spacing_m");
  s.synthetic.radius_vox = r.number(vol, "volume", "radius_vox");
}

void parse_isosurface(const Reader& r, const json& root, Scene& s) {
  if (!root.contains("isovalue")) r.fail("isovalue", "is required");
  s.hri.tau = r.number(root, "", "isovalue");
  const std::string inside = r.string(root, "", "inside", "above");
  if (inside == "above") s.hri.inside = core::InsideIs::kAbove;
  else if (inside == "below") s.hri.inside = core::InsideIs::kBelow;
  else r.fail("inside", "must be \"above\" (value > isovalue is inside) or \"below\", got \"" + inside + "\"");
}

// The servo's variant, intersection and normal rules; the paper variant takes no other.
void parse_servo_rules(const Reader& r, const json& sv, Scene& s) {
  const std::string isect = r.string(sv, "servo", "intersection", "linear");
  if (isect == "linear") s.hri.intersection = servo::Intersection::kLinear;
  else if (isect == "secant") s.hri.intersection = servo::Intersection::kSecant;
  else if (isect == "bisection") s.hri.intersection = servo::Intersection::kBisection;
  else r.fail("servo.intersection", "must be \"linear\" (the paper), \"secant\" or \"bisection\", got \"" + isect + "\"");
  s.hri.intersection_steps = r.integer(sv, "servo", "intersection_steps");
  const std::string normal = r.string(sv, "servo", "normal", "samples");
  if (normal == "samples") s.hri.normal = servo::NormalSource::kSamples;
  else if (normal == "central") s.hri.normal = servo::NormalSource::kCentral;
  else if (normal == "exact") s.hri.normal = servo::NormalSource::kTrilinearExact;
  else r.fail("servo.normal", "must be \"samples\", \"central\" (the paper) or \"exact\", got \"" + normal + "\"");
  // The paper variant is Figure 2 as printed: LinearInterpolation and central differences at p
  // (servo/hri.h). A scene that asks it for another rule would be silently overridden: refuse.
  if (s.hri.variant == servo::Variant::kPaper && (isect != "linear" || normal != "central") &&
      (sv.contains("intersection") || sv.contains("normal")))
    r.fail(isect != "linear" ? "servo.intersection" : "servo.normal",
           "the \"paper\" variant always uses linear intersection and central-difference normals "
           "(Figure 2 as printed); remove the key or use \"variant\": \"robust\", got \"" +
               (isect != "linear" ? isect : normal) + "\"");
}

void parse_friction(const Reader& r, const json& sv, Scene& s) {
  if (!sv.contains("friction")) return;
  const json& fr = sv.at("friction");
  r.only(fr, "servo.friction", scene_keys("servo.friction"));
  s.hri.friction.mu_s = r.number(fr, "servo.friction", "mu_s");
  s.hri.friction.mu_d = r.number(fr, "servo.friction", "mu_d");
  s.hri.friction.viscous_n_s_per_m = r.number(fr, "servo.friction", "viscous_n_s_per_m");
  if (s.hri.friction.mu_d > s.hri.friction.mu_s)
    r.fail("servo.friction.mu_d", "must not exceed mu_s (" + std::to_string(s.hri.friction.mu_s) + "), got " +
                                      fr.at("mu_d").dump());
}

// The spherical tool: its centre is the HIP, its surface is kept outside the isosurface
// (robust variant only; servo/hri.h, "Spherical tool").
void parse_tool(const Reader& r, const json& sv, Scene& s) {
  if (!sv.contains("tool")) return;
  const json& tl = sv.at("tool");
  if (!tl.is_object()) r.fail("servo.tool", "must be an object {\"radius_mm\": r} or {\"point\": true}, got " + tl.dump());
  r.only(tl, "servo.tool", scene_keys("servo.tool"));
  s.point_probe = r.boolean(tl, "servo.tool", "point", false);
  if (s.point_probe && tl.contains("radius_mm"))
    r.fail("servo.tool.point", "a point has no radius: give \"point\": true or \"radius_mm\", not both");
  s.hri.tool_radius_m = 1e-3 * r.number(tl, "servo.tool", "radius_mm");
  if (s.hri.tool_radius_m > 0 && s.hri.variant == servo::Variant::kPaper)
    r.fail("servo.tool.radius_mm", "the \"paper\" variant renders a point (Figure 2 as printed); use "
                                   "\"variant\": \"robust\" for a tool of radius " + tl.at("radius_mm").dump() + " mm");
  if (s.hri.tool_radius_m > 0 && (s.hri.friction.any() || s.hri.force_shading))
    r.fail("servo.tool.radius_mm", "friction and force shading are not implemented for a spherical tool; "
                                   "remove them or set radius_mm to 0, got " + tl.at("radius_mm").dump());
}

// The button's carve or drill brush (the one the probe carries, edits.button) is felt as the
// spherical tool of its radius unless the scene gives the tool (servo.tool.radius_mm) or
// keeps the point (servo.tool.point). Without a button the brush never cuts at the probe.
void tool_from_brush(const Reader& r, Scene& s) {
  const std::string& kind = s.edits.brush.kind;
  if (!s.edits.present || s.edits.button_down.empty() || (kind != "carve" && kind != "drill")) return;
  if (s.point_probe || s.hri.tool_radius_m > 0) return;
  if (s.hri.variant == servo::Variant::kPaper || s.hri.friction.any() || s.hri.force_shading)
    r.fail("edits.brush", "a " + kind + " brush is felt as the spherical tool of its radius, which the \"paper\" "
                          "variant, friction and force shading do not render; add \"servo\": {\"tool\": {\"point\": true}} "
                          "to keep the point");
  s.hri.tool_radius_m = 1e-3 * s.edits.brush.radius_mm;
  s.tool_from_brush = true;
}

void parse_servo(const Reader& r, const json& root, Scene& s) {
  const json& sv = r.section(root, "servo");
  r.only(sv, "servo", scene_keys("servo"));
  const std::string variant = r.string(sv, "servo", "variant", "robust");
  if (variant == "robust") s.hri.variant = servo::Variant::kRobust;
  else if (variant == "paper") s.hri.variant = servo::Variant::kPaper;
  else r.fail("servo.variant", "must be \"robust\" (the default) or \"paper\" (Figure 2 as printed), got \"" + variant + "\"");
  s.hri.stiffness_n_per_m = r.number(sv, "servo", "stiffness_n_per_m");
  s.hri.damping_n_s_per_m = r.number(sv, "servo", "damping_n_s_per_m");
  s.hri.plane_update_period = r.integer(sv, "servo", "plane_update_period");
  s.hri.rate_hz = r.number(sv, "servo", "rate_hz");
  s.hri.force_limit_n = r.number(sv, "servo", "force_limit_n");
  parse_servo_rules(r, sv, s);
  s.hri.force_shading = r.boolean(sv, "servo", "force_shading", false);
  // Default 20 ms (robust variant): every force step a plane update causes is ramped.
  s.hri.recovery_time_s = r.number(sv, "servo", "recovery_time_s",
                                   s.hri.variant == servo::Variant::kPaper ? 0.0 : 0.02);
  parse_friction(r, sv, s);
  parse_tool(r, sv, s);
  s.allow_unstable_stiffness = r.boolean(sv, "servo", "allow_unstable_stiffness", false);
  s.passivity_control = r.boolean(sv, "servo", "passivity_control", false);
}

// The force is stiffness x the hand's travel past the surface [N], the travel being the
// probe's depth in the volume / workspace_scale: at 1e-9 a touch asks for the force limit
// at once (forces jump between 0 and the limit), at 1000 the whole volume lies within a
// fraction of a millimetre of hand travel (no force to feel). Outside [1e-4, 10] no scene
// can be felt on a desk-sized device.
void check_workspace_scale(const Reader& r, const json& dv, const Scene& s) {
  const double scale = s.workspace_scale;
  if (scale >= kMinWorkspaceScale && scale <= kMaxWorkspaceScale) return;
  const double press_n = s.hri.stiffness_n_per_m * 1e-3 / scale;  // a 1 mm press in the volume
  std::ostringstream e;
  e << "must be in [" << kMinWorkspaceScale << ", " << kMaxWorkspaceScale << "] (world [m] per device [m]), got "
    << dv.at("workspace_scale").dump() << ": 1 mm of hand motion would move the probe " << scale
    << " mm in the volume, and a press 1 mm into its surface would take " << 1.0 / scale
    << " mm of hand travel and ask for " << press_n << " N (stiffness " << s.hri.stiffness_n_per_m
    << " N/m x that travel; force limit " << s.hri.force_limit_n << " N)"
    << (scale < kMinWorkspaceScale ? ": every touch jumps to the force limit" : ": too little force to feel");
  r.fail("device.workspace_scale", e.str());
}

// Colgate and Schenkel's passivity bound K_max = 2 (b - |B|) / T, with b the damping at
// the handle (device + hand), B the servo's damping, T the servo period: a stiffer wall
// may buzz or push the hand away. Refused unless servo.allow_unstable_stiffness says the
// scene means it (stability experiments); the run then warns and reports it.
void check_stiffness(const Reader& r, const Scene& s) {
  const double b = s.device.damping_n_s_per_m + s.device.hand_damping_n_s_per_m;
  const double bound = sim::colgate_k_max(b, s.hri.damping_n_s_per_m, 1.0 / s.hri.rate_hz);
  if (s.hri.stiffness_n_per_m <= bound || s.allow_unstable_stiffness) return;
  std::ostringstream e;
  e << "is above the stability bound K_max = 2 (b - |B|) / T = " << bound << " N/m (b = device + hand damping "
    << b << " N s/m, B = servo.damping_n_s_per_m " << s.hri.damping_n_s_per_m << ", T = 1 / rate_hz " << 1e3 / s.hri.rate_hz
    << " ms), got " << s.hri.stiffness_n_per_m
    << ": the contact may buzz; lower it or the servo damping, raise servo.rate_hz, or set "
       "\"servo\": {\"allow_unstable_stiffness\": true} to run it anyway";
  r.fail("servo.stiffness_n_per_m", e.str());
}

// After the servo section: the mass check needs the servo rate.
void parse_device(const Reader& r, const json& root, Scene& s) {
  const json& dv = r.section(root, "device");
  r.only(dv, "device", scene_keys("device"));
  s.device.mass_kg = r.number(dv, "device", "mass_kg");
  s.device.damping_n_s_per_m = r.number(dv, "device", "damping_n_s_per_m");
  s.device.coulomb_friction_n = r.number(dv, "device", "coulomb_friction_n");
  s.device.encoder_resolution_m = r.number(dv, "device", "encoder_resolution_m");
  s.device.force_max_n = r.number(dv, "device", "force_max_n");
  s.device.hand_stiffness_n_per_m = r.number(dv, "device", "hand_stiffness_n_per_m");
  s.device.hand_damping_n_s_per_m = r.number(dv, "device", "hand_damping_n_s_per_m");
  s.device.substeps = r.integer(dv, "device", "substeps");
  // The simulated device raises its substeps to integrate stably (sim_device.h); past
  // 10000 per servo period the device is too light for its hand to simulate.
  const double dt = 1.0 / s.hri.rate_hz;
  if (sim::min_stable_substeps(s.device, dt) > 10000) {
    std::ostringstream e;
    e << "must be at least " << sim::min_stable_mass_kg(s.device, dt, 10000)
      << " kg to simulate stably with the hand (" << s.device.hand_stiffness_n_per_m << " N/m, "
      << s.device.hand_damping_n_s_per_m << " N s/m) in at most 10000 substeps per " << dt * 1e3
      << " ms servo period, got " << dv.at("mass_kg").dump();
    r.fail("device.mass_kg", e.str());
  }
  s.workspace_scale = r.number(dv, "device", "workspace_scale");
  check_workspace_scale(r, dv, s);
  s.allow_no_watchdog = r.boolean(dv, "device", "allow_no_watchdog", false);
  s.link_max_force_n = r.number(dv, "device", "link_max_force_n");
  s.link_round_trip_s = 1e-3 * r.number(dv, "device", "link_round_trip_ms");
  s.link_passivity_control = r.boolean(dv, "device", "link_passivity_control", false);
  s.hri.world_per_device = s.workspace_scale;
}

void parse_script(const Reader& r, const json& root, Scene& s) {
  const json& sc = r.section(root, "script");
  r.only(sc, "script", scene_keys("script"));
  auto& p = s.script;
  p.ray_origin_frac = r.vec3(sc, "script", "ray_origin_frac", p.ray_origin_frac);
  for (int a = 0; a < 3; ++a)
    if (p.ray_origin_frac[a] < sim::kRayOriginFracMin || p.ray_origin_frac[a] > sim::kRayOriginFracMax) {
      std::ostringstream e;
      e << "each must be in [" << sim::kRayOriginFracMin << ", " << sim::kRayOriginFracMax
        << "] (fractions of the volume box), got " << sc.at("ray_origin_frac").dump();
      r.fail("script.ray_origin_frac", e.str());
    }
  p.ray_direction = r.vec3(sc, "script", "ray_direction", p.ray_direction);
  if (core::norm(p.ray_direction) == 0.0) r.fail("script.ray_direction", "must not be [0, 0, 0]");
  p.stroke_direction = r.vec3(sc, "script", "stroke_direction", p.stroke_direction);
  p.approach_distance_m = r.number(sc, "script", "approach_distance_m");
  p.approach_speed_m_s = r.number(sc, "script", "approach_speed_m_s");
  p.press_depth_m = r.number(sc, "script", "press_depth_m");
  p.press_speed_m_s = r.number(sc, "script", "press_speed_m_s");
  p.hold_s = r.number(sc, "script", "hold_s");
  p.stroke_length_m = r.number(sc, "script", "stroke_length_m");
  p.stroke_speed_m_s = r.number(sc, "script", "stroke_speed_m_s");
  p.rest_s = r.number(sc, "script", "rest_s");
  p.lift_retrace = r.boolean(sc, "script", "lift_retrace", p.lift_retrace);
  p.plan = r.string(sc, "script", "plan", p.plan);
  if (p.plan != "ray" && p.plan != "surface")
    r.fail("script.plan", "must be \"ray\" (the press at press_depth_m, the stroke re-cast along the first normal) or "
                          "\"surface\" (planned on the true isosurface), got \"" + p.plan + "\"");
  p.press_force_fraction = r.number(sc, "script", "press_force_fraction");
}

// One entry of "materials.list": {"name", "label" | "range", "stiffness_n_per_m", "mu_s",
// "mu_d", "rate", "density_scale", "color", "critical", "margin_mm"}.
materials::Material parse_material(const Reader& r, const json& m, const std::string& f, bool label_map, bool seg) {
  constexpr std::string_view kSec = "materials.list";
  r.only(m, f, scene_keys(kSec));
  materials::Material out;
  if (!m.contains("name")) r.fail(f + ".name", "is required");
  out.name = r.string(m, f, "name", "");
  if (out.name.empty()) r.fail(f + ".name", "must not be empty");
  if (!label_map && m.contains("label"))
    r.fail(f + ".label", "applies to a label map (\"materials.labels\"); a transfer function gives \"range\"");
  if (label_map && m.contains("range"))
    r.fail(f + ".range", "applies to a transfer function; with \"materials.labels\" give \"label\"");
  if (label_map && !seg && !m.contains("label")) r.fail(f + ".label", "is required with a label map (its value in the map)");
  if (m.contains("label")) out.label = r.integer(m, f, "label", {}, kSec);
  if (!label_map) {
    if (!m.contains("range")) r.fail(f + ".range", "is required with a transfer function: [lo, hi) in the volume's units");
    const json& v = m.at("range");
    if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number() ||
        !std::isfinite(v[0].get<double>()) || !std::isfinite(v[1].get<double>()) || !(v[0].get<double>() < v[1].get<double>()))
      r.fail(f + ".range", "must be [lo, hi) with lo < hi, finite, got " + v.dump());
    out.range_lo = v[0].get<double>();
    out.range_hi = v[1].get<double>();
  }
  out.stiffness_n_per_m = r.number(m, f, "stiffness_n_per_m", {}, kSec);
  out.mu_s = r.number(m, f, "mu_s", {}, kSec);
  out.mu_d = r.number(m, f, "mu_d", {}, kSec);
  if (out.mu_d > out.mu_s) r.fail(f + ".mu_d", "must be at most mu_s (" + std::to_string(out.mu_s) + "), got " + m.at("mu_d").dump());
  out.rate = m.contains("rate") ? r.number(m, f, "rate", {}, kSec) : -1;  // absent: the drill's own
  out.density_scale = r.number(m, f, "density_scale", {}, kSec);
  if (m.contains("color")) {
    const json& c = m.at("color");
    if (!c.is_array() || c.size() != 3) r.fail(f + ".color", "must be [r, g, b], each in [0, 1], got " + c.dump());
    for (std::size_t k = 0; k < 3; ++k) {
      if (!c[k].is_number() || !(c[k].get<double>() >= 0.0 && c[k].get<double>() <= 1.0))
        r.fail(f + ".color", "must be [r, g, b], each in [0, 1], got " + c.dump());
      out.color[k] = c[k].get<double>();
    }
    out.has_color = true;
  }
  out.critical = r.boolean(m, f, "critical", false);
  out.margin_mm = r.number(m, f, "margin_mm", {}, kSec);
  // A margin is the warning distance of a critical material: on another it would be ignored,
  // and a critical one without it could never warn.
  if (!out.critical && out.margin_mm > 0)
    r.fail(f + ".margin_mm", "only a critical material has a margin, got " + m.at("margin_mm").dump());
  if (out.critical && out.margin_mm <= 0)
    r.fail(f + ".margin_mm", "is required above 0 for a critical material, got " +
                                 (m.contains("margin_mm") ? m.at("margin_mm").dump() : std::string("0 (absent)")));
  return out;
}

// "materials": {"labels": PATH (a label map or .seg.nrrd; absent: a transfer function),
//               "list": [material, ...]}
void parse_materials(const Reader& r, const json& root, const std::string& path, materials::MaterialsSpec& spec) {
  if (!root.contains("materials")) return;
  const json& m = root.at("materials");
  r.only(m, "materials", scene_keys("materials"));
  spec.present = true;
  if (m.contains("labels")) {
    const std::string p = r.string(m, "materials", "labels", "");
    if (p.empty()) r.fail("materials.labels", "must not be empty");
    const fs::path pp(p);
    spec.labels_path = pp.is_absolute() ? p : (fs::path(path).parent_path() / pp).lexically_normal().string();
  }
  if (!m.contains("list")) r.fail("materials.list", "is required: the materials, [{\"name\": ..., ...}, ...]");
  const json& list = m.at("list");
  if (!list.is_array() || list.empty() || list.size() > 255)
    r.fail("materials.list", "must be an array of 1 to 255 materials, got " + (list.is_array() ? std::to_string(list.size()) + " entries" : list.dump()));
  const bool label_map = !spec.labels_path.empty(), seg = materials::is_seg_nrrd(spec.labels_path);
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string f = "materials.list[" + std::to_string(i) + "]";
    const materials::Material mat = parse_material(r, list[i], f, label_map, seg);
    for (const materials::Material& o : spec.list) {
      if (o.name == mat.name) r.fail(f + ".name", "\"" + mat.name + "\" names an earlier material too");
      if (label_map && mat.label >= 0 && o.label == mat.label)
        r.fail(f + ".label", std::to_string(mat.label) + " is \"" + o.name + "\"'s label too");
      if (!label_map && mat.range_lo < o.range_hi && o.range_lo < mat.range_hi)
        r.fail(f + ".range", list[i].at("range").dump() + " overlaps \"" + o.name + "\"'s");
    }
    spec.list.push_back(mat);
  }
}

}  // namespace

Scene parse_scene(const std::string& text, const std::string& path) {
  const json root = parse_json_once_each(text, path);
  const Reader r(path);
  r.only(root, "", scene_keys(""));
  Scene s;
  s.file = path;
  parse_name(r, root, path, s);
  parse_volume(r, root, path, s);
  parse_isosurface(r, root, s);
  parse_servo(r, root, s);
  parse_device(r, root, s);
  check_stiffness(r, s);
  parse_script(r, root, s);
  parse_engine(r, r.section(root, "engine"), s.engine);
  if (root.contains("edits")) {
    parse_edits(r, root.at("edits"), s.edits);
    if (s.engine.mode != "sparse")
      r.fail("edits", "edits publish bricked snapshots brick by brick: they need \"engine\": {\"mode\": \"sparse\"}, got \"" +
                          s.engine.mode + "\"");
    tool_from_brush(r, s);
  }
  parse_materials(r, root, path, s.materials);
  const json& out = r.section(root, "outputs");
  r.only(out, "outputs", scene_keys("outputs"));
  s.write_trace = r.boolean(out, "outputs", "trace_csv", true);
  s.draw_plots = r.boolean(out, "outputs", "plots", true);
  check_script_length(r, s);
  return s;
}

Scene load_scene(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw SceneError(path + ": no such scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path + ": cannot open the scene file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_scene(ss.str(), path);
}

}  // namespace isotouch::io
