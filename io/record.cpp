// record.cpp - recordings as JSON lines (nlohmann-json), written atomically, read back
// bit for bit with every problem named (file, line, record, field, value). See record.h.
#include "isotouch/io/record.h"

#include "isotouch/io/files.h"

#include "isotouch/io/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <limits>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <zlib.h>

namespace isotouch::io {
using core::to_string;
using session::to_string;
using session::EditEvent;
namespace {

using json = nlohmann::json;
/// Written with the keys in the order given (readable lines: "k" and "t" first).
using ojson = nlohmann::ordered_json;

/// Longest line the loader accepts [bytes]: the header carries the scene text (scenes are
/// a few kB); anything this long is not a recording.
constexpr std::size_t kMaxLine = std::size_t(64) << 20;
/// Deepest bracket nesting accepted before parsing (a recording nests 3 deep).
constexpr int kMaxDepth = 16;

// ---------------------------------------------------------------- writing

ojson vec_json(const core::Vec3& v) { return ojson::array({v.x, v.y, v.z}); }

bool finite3(const core::Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

std::string num(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

ojson brush_json(const session::Brush& b) {
  return ojson{{"kind", session::to_string(b.kind)},
              {"centre_m", vec_json(b.centre_m)},
              {"radius_m", b.radius_m},
              {"strength", b.strength},
              {"falloff", b.falloff},
              {"targets",
               {{"material", double(b.targets.material)},
                {"empty", double(b.targets.empty)},
                {"density_scale", double(b.targets.density_scale)}}},
              {"force_n", b.force_n},
              {"force_threshold_n", b.force_threshold_n},
              {"rate", b.rate},
              {"dt_s", b.dt_s}};
}

/// Every double of a brush, with its field name (for the finiteness check on save).
std::vector<std::pair<const char*, double>> brush_numbers(const session::Brush& b) {
  return {{"centre_m[0]", b.centre_m.x}, {"centre_m[1]", b.centre_m.y}, {"centre_m[2]", b.centre_m.z},
          {"radius_m", b.radius_m}, {"strength", b.strength}, {"falloff", b.falloff},
          {"targets.material", b.targets.material}, {"targets.empty", b.targets.empty},
          {"targets.density_scale", b.targets.density_scale}, {"force_n", b.force_n},
          {"force_threshold_n", b.force_threshold_n}, {"rate", b.rate}, {"dt_s", b.dt_s}};
}

void check_tick(const RecordedTick& t, std::size_t k, const std::string& name) {
  const std::string at = name + ": tick " + std::to_string(k) + ": field '";
  if (!std::isfinite(t.t_s)) throw RecordingError(at + "t' must be finite, got " + num(t.t_s));
  if (!finite3(t.hip_m))
    throw RecordingError(at + "hip' must be finite, got " + num(t.hip_m.x) + " " + num(t.hip_m.y) + " " + num(t.hip_m.z));
  if (!finite3(t.force_n))
    throw RecordingError(at + "force' must be finite, got " + num(t.force_n.x) + " " + num(t.force_n.y) + " " +
                         num(t.force_n.z));
  if (!finite3(t.vhip_m))
    throw RecordingError(at + "vhip' must be finite, got " + num(t.vhip_m.x) + " " + num(t.vhip_m.y) + " " +
                         num(t.vhip_m.z));
}

void check_edit(const EditEvent& e, std::size_t i, long prev_tick, std::size_t ticks, const std::string& name) {
  const std::string at = name + ": edit " + std::to_string(i) + " (" + to_string(e.kind) + "): field '";
  if (e.tick < 0 || std::size_t(e.tick) >= ticks)
    throw RecordingError(at + "tick' = " + std::to_string(e.tick) + " is not one of the " + std::to_string(ticks) +
                         " recorded ticks");
  if (e.tick < prev_tick)
    throw RecordingError(at + "tick' = " + std::to_string(e.tick) + " comes after an edit of tick " +
                         std::to_string(prev_tick) + " (edits must be in the order applied)");
  if (!std::isfinite(e.t_s)) throw RecordingError(at + "t' must be finite, got " + num(e.t_s));
  for (const auto& [field, v] : brush_numbers(e.brush))
    if (!std::isfinite(v)) throw RecordingError(at + "brush." + field + "' must be finite, got " + num(v));
}

// ---------------------------------------------------------------- reading

/// Where a record is, for messages: "FILE: line 12 (tick 10)".
struct Where {
  const std::string& name;
  std::size_t line;
  std::string record;
  std::string at(const std::string& field) const {
    return name + ": line " + std::to_string(line) + " (" + record + "): field '" + field + "'";
  }
};

std::string shown(const json& v) {
  std::string s = v.dump(-1, ' ', false, json::error_handler_t::replace);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

const json& member(const json& obj, const char* field, const Where& w) {
  const auto it = obj.find(field);
  if (it == obj.end()) throw RecordingError(w.at(field) + ": missing");
  return *it;
}

double finite_number(const json& v, const std::string& field, const Where& w) {
  if (!v.is_number()) throw RecordingError(w.at(field) + ": must be a finite number, got " + shown(v));
  const double d = v.get<double>();
  if (!std::isfinite(d)) throw RecordingError(w.at(field) + ": must be a finite number, got " + shown(v));
  return d;
}
double member_number(const json& obj, const char* field, const Where& w) {
  return finite_number(member(obj, field, w), std::string(field), w);
}

long integer(const json& obj, const char* field, const Where& w) {
  const json& v = member(obj, field, w);
  if (!v.is_number_integer()) throw RecordingError(w.at(field) + ": must be an integer, got " + shown(v));
  if (v.is_number_unsigned() && v.get<std::uint64_t>() > std::uint64_t(std::numeric_limits<long>::max()))
    throw RecordingError(w.at(field) + ": out of range, got " + shown(v));
  return v.get<long>();
}

std::string text(const json& obj, const char* field, const Where& w) {
  const json& v = member(obj, field, w);
  if (!v.is_string()) throw RecordingError(w.at(field) + ": must be a string, got " + shown(v));
  return v.get<std::string>();
}

bool boolean(const json& obj, const char* field, const Where& w) {
  const json& v = member(obj, field, w);
  if (!v.is_boolean()) throw RecordingError(w.at(field) + ": must be true or false, got " + shown(v));
  return v.get<bool>();
}

core::Vec3 vec3(const json& obj, const char* field, const Where& w) {
  const json& v = member(obj, field, w);
  if (!v.is_array() || v.size() != 3)
    throw RecordingError(w.at(field) + ": must be an array of 3 finite numbers, got " + shown(v));
  double c[3];
  for (std::size_t i = 0; i < 3; ++i) c[i] = finite_number(v[i], std::string(field) + "[" + std::to_string(i) + "]", w);
  return {c[0], c[1], c[2]};
}

/// A float written as a double: must be finite and exactly a float.
float exact_float(const json& obj, const char* field, const std::string& prefix, const Where& w) {
  const double d = finite_number(member(obj, field, w), prefix + field, w);
  const float f = float(d);
  if (double(f) != d) throw RecordingError(w.at(prefix + field) + ": must be a float value, got " + num(d));
  return f;
}

/// Unknown keys are refused (a misspelt field would otherwise be silently defaulted).
void only_keys(const json& obj, std::initializer_list<const char*> keys, const std::string& prefix, const Where& w) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    bool known = false;
    for (const char* k : keys) known = known || it.key() == k;
    if (!known) throw RecordingError(w.at(prefix + it.key()) + ": unknown field");
  }
}

session::BrushKind brush_kind(const std::string& s, const Where& w) {
  for (auto k : {session::BrushKind::kAdd, session::BrushKind::kCarve, session::BrushKind::kSmooth, session::BrushKind::kDrill})
    if (s == session::to_string(k)) return k;
  throw RecordingError(w.at("brush.kind") + ": unknown brush kind \"" + s + "\" (add, carve, smooth, drill)");
}

session::Brush parse_brush(const json& b, const Where& w) {
  if (!b.is_object()) throw RecordingError(w.at("brush") + ": must be an object, got " + shown(b));
  only_keys(b, {"kind", "centre_m", "radius_m", "strength", "falloff", "targets", "force_n", "force_threshold_n", "rate", "dt_s"},
            "brush.", w);
  session::Brush out;
  const json& kind = member(b, "kind", w);
  if (!kind.is_string()) throw RecordingError(w.at("brush.kind") + ": must be a string, got " + shown(kind));
  out.kind = brush_kind(kind.get<std::string>(), w);
  const json& c = member(b, "centre_m", w);
  if (!c.is_array() || c.size() != 3)
    throw RecordingError(w.at("brush.centre_m") + ": must be an array of 3 finite numbers, got " + shown(c));
  out.centre_m = {finite_number(c[0], "brush.centre_m[0]", w), finite_number(c[1], "brush.centre_m[1]", w),
                  finite_number(c[2], "brush.centre_m[2]", w)};
  const std::pair<const char*, double*> doubles[] = {
      {"radius_m", &out.radius_m}, {"strength", &out.strength}, {"falloff", &out.falloff}, {"force_n", &out.force_n},
      {"force_threshold_n", &out.force_threshold_n}, {"rate", &out.rate}, {"dt_s", &out.dt_s}};
  for (const auto& [field, dst] : doubles) *dst = finite_number(member(b, field, w), std::string("brush.") + field, w);
  const json& t = member(b, "targets", w);
  if (!t.is_object()) throw RecordingError(w.at("brush.targets") + ": must be an object, got " + shown(t));
  only_keys(t, {"material", "empty", "density_scale"}, "brush.targets.", w);
  out.targets.material = exact_float(t, "material", "brush.targets.", w);
  out.targets.empty = exact_float(t, "empty", "brush.targets.", w);
  out.targets.density_scale = exact_float(t, "density_scale", "brush.targets.", w);
  return out;
}

EditEvent::Kind edit_kind(const std::string& s, const Where& w) {
  for (auto k : {EditEvent::Kind::kBrush, EditEvent::Kind::kBeginStroke, EditEvent::Kind::kEndStroke,
                 EditEvent::Kind::kUndo, EditEvent::Kind::kRedo})
    if (s == to_string(k)) return k;
  throw RecordingError(w.at("edit") + ": unknown edit kind \"" + s + "\" (brush, begin_stroke, end_stroke, undo, redo)");
}

/// Nesting depth of brackets outside strings: refuses garbage that would only make the
/// parser work (nlohmann is iterative, but there is no reason to build deep garbage).
bool too_deep(const std::string& line) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (char ch : line) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (ch == '\\') escaped = true;
      else if (ch == '"') in_string = false;
    } else if (ch == '"') {
      in_string = true;
    } else if (ch == '[' || ch == '{') {
      if (++depth > kMaxDepth) return true;
    } else if (ch == ']' || ch == '}') {
      --depth;
    }
  }
  return false;
}

json parse_line(const std::string& line, const std::string& name, std::size_t n) {
  const std::string at = name + ": line " + std::to_string(n) + ": ";
  if (line.size() > kMaxLine) throw RecordingError(at + "longer than " + std::to_string(kMaxLine) + " bytes: not a recording");
  if (too_deep(line)) throw RecordingError(at + "nested deeper than " + std::to_string(kMaxDepth) + ": not a recording");
  try {
    json j = json::parse(line);
    if (!j.is_object()) throw RecordingError(at + "a record must be a JSON object, got " + shown(j));
    return j;
  } catch (const json::exception& e) {
    throw RecordingError(at + "not valid JSON: " + e.what());
  }
}

RecordedEditSession parse_edit_session(const json& h, const Where& w) {
  const json& e = h.at("edit_session");
  if (!e.is_object()) throw RecordingError(w.at("edit_session") + ": must be an object, got " + shown(e));
  only_keys(e, {"gpu_brushes", "history_limit_mib", "edit_period_s"}, "edit_session.", w);
  RecordedEditSession s;
  const json& gpu = member(e, "gpu_brushes", w);
  if (!gpu.is_boolean()) throw RecordingError(w.at("edit_session.gpu_brushes") + ": must be true or false, got " + shown(gpu));
  s.gpu_brushes = gpu.get<bool>();
  s.history_limit_mib = finite_number(member(e, "history_limit_mib", w), "edit_session.history_limit_mib", w);
  if (!(s.history_limit_mib > 0))
    throw RecordingError(w.at("edit_session.history_limit_mib") + ": must be > 0, got " + num(s.history_limit_mib));
  if (e.contains("edit_period_s")) {
    s.edit_period_s = finite_number(member(e, "edit_period_s", w), "edit_session.edit_period_s", w);
    if (!(s.edit_period_s >= 0))
      throw RecordingError(w.at("edit_session.edit_period_s") + ": must be >= 0, got " + num(s.edit_period_s));
  }
  return s;
}

core::Isosurface parse_isovalue(const json& h, const Where& w) {
  const json& e = h.at("isovalue");
  if (!e.is_object()) throw RecordingError(w.at("isovalue") + ": must be an object, got " + shown(e));
  only_keys(e, {"tau", "inside"}, "isovalue.", w);
  core::Isosurface iso;
  iso.tau = finite_number(member(e, "tau", w), "isovalue.tau", w);
  const json& inside = member(e, "inside", w);
  if (inside == "above") iso.inside = core::InsideIs::kAbove;
  else if (inside == "below") iso.inside = core::InsideIs::kBelow;
  else throw RecordingError(w.at("isovalue.inside") + ": must be \"above\" or \"below\", got " + shown(inside));
  return iso;
}

std::vector<std::size_t> parse_history_restarts(const json& h, const Where& w) {
  const json& a = h.at("history_restarts");
  if (!a.is_array()) throw RecordingError(w.at("history_restarts") + ": must be an array of edit counts, got " + shown(a));
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::string field = "history_restarts[" + std::to_string(i) + "]";
    if (!a[i].is_number_integer() || a[i].get<long long>() < 0)
      throw RecordingError(w.at(field) + ": must be an integer >= 0, got " + shown(a[i]));
    const std::size_t n = a[i].get<std::size_t>();
    if (!out.empty() && n < out.back())
      throw RecordingError(w.at(field) + ": " + std::to_string(n) + " is less than the one before it (" +
                           std::to_string(out.back()) + "): must be ascending");
    out.push_back(n);
  }
  return out;
}

void parse_header(const json& h, Recording& r, const Where& w) {
  const std::string format = text(h, "format", w);
  if (format != kRecordingFormat)
    throw RecordingError(w.at("format") + ": \"" + format.substr(0, 60) + "\" is not \"" + kRecordingFormat + "\"");
  const long v = integer(h, "format_version", w);
  if (v < 1 || v > 3)
    throw RecordingError(w.at("format_version") + ": " + std::to_string(v) + " is not supported (this isotouch reads 1, 2 and 3)");
  r.format_version = int(v);
  if (v == 1) only_keys(h, {"format", "format_version", "scene_path", "scene_text", "rate_hz"}, "", w);
  else if (v == 2) only_keys(h, {"format", "format_version", "scene_path", "scene_text", "rate_hz", "volume_crc32"}, "", w);
  else
    only_keys(h, {"format", "format_version", "scene_path", "scene_text", "rate_hz", "volume_crc32", "edit_session",
                  "isovalue", "history_restarts"},
              "", w);
  if (h.contains("edit_session")) r.edit_session = parse_edit_session(h, w);
  if (h.contains("isovalue")) r.isovalue = parse_isovalue(h, w);
  if (h.contains("history_restarts")) r.history_restarts = parse_history_restarts(h, w);
  if (v >= 2) {
    const long crc = integer(h, "volume_crc32", w);
    if (crc < 0 || crc > long(UINT32_MAX))
      throw RecordingError(w.at("volume_crc32") + ": must be in [0, 4294967295], got " + std::to_string(crc));
    r.volume_crc32 = std::uint32_t(crc);
  }
  r.scene_path = text(h, "scene_path", w);
  r.scene_text = text(h, "scene_text", w);
  r.rate_hz = member_number(h, "rate_hz", w);
  if (!(r.rate_hz > 0)) throw RecordingError(w.at("rate_hz") + ": must be > 0, got " + num(r.rate_hz));
}

/// A format 3 tick's passivity stage: "pt" (its clock, [0, 1e9) s) and "sent", both or neither.
void parse_passivity(const json& j, RecordedTick& t, const Where& w) {
  if (j.contains("pt") != j.contains("sent"))
    throw RecordingError(w.at(j.contains("pt") ? "sent" : "pt") + ": missing (\"pt\" and \"sent\" come together)");
  if (!j.contains("pt")) return;
  const double pt = member_number(j, "pt", w);
  if (!(pt >= 0) || !(pt < 1e9)) throw RecordingError(w.at("pt") + ": must be in [0, 1e9) s, got " + num(pt));
  // A held tick (paused, device not ok) wrote an exact zero without the stage: no clock.
  if (t.held) throw RecordingError(w.at("pt") + ": a held tick has no passivity stage, got " + num(pt) + " s");
  t.passivity_clock_s = pt;
  t.sent_n = vec3(j, "sent", w);
}

void parse_tick(const json& j, Recording& r, const Where& w) {
  if (r.format_version == 1) only_keys(j, {"k", "t", "hip", "button", "force"}, "", w);
  else if (r.format_version == 2) only_keys(j, {"k", "t", "hip", "button", "force", "vhip", "version", "fault"}, "", w);
  else only_keys(j, {"k", "t", "dt", "hip", "button", "force", "vhip", "version", "fault", "held", "reset", "pt", "sent"}, "", w);
  const long k = integer(j, "k", w);
  if (k != long(r.ticks.size()))
    throw RecordingError(w.at("k") + ": expected tick " + std::to_string(r.ticks.size()) + ", got " + std::to_string(k));
  RecordedTick t;
  t.t_s = member_number(j, "t", w);
  if (!r.ticks.empty() && !(t.t_s > r.ticks.back().t_s))
    throw RecordingError(w.at("t") + ": " + num(t.t_s) + " s is not after the previous tick's " + num(r.ticks.back().t_s) + " s");
  t.hip_m = vec3(j, "hip", w);
  t.button = boolean(j, "button", w);
  t.force_n = vec3(j, "force", w);
  if (r.format_version >= 2) {
    t.vhip_m = vec3(j, "vhip", w);
    const long version = integer(j, "version", w);
    if (version < 1) throw RecordingError(w.at("version") + ": must be >= 1 (a published snapshot), got " + std::to_string(version));
    t.version = std::uint64_t(version);
    if (j.contains("fault")) {
      t.fault = boolean(j, "fault", w);
      if (!t.fault) throw RecordingError(w.at("fault") + ": written only when true, got false");
    }
  }
  if (r.format_version >= 3) {
    t.dt_s = member_number(j, "dt", w);
    if (!(t.dt_s >= 0) || !(t.dt_s < 3600))
      throw RecordingError(w.at("dt") + ": must be in [0, 3600) s, got " + num(t.dt_s));
    for (auto [key, flag] : {std::pair{"held", &t.held}, std::pair{"reset", &t.reset}})
      if (j.contains(key)) {
        *flag = boolean(j, key, w);
        if (!*flag) throw RecordingError(w.at(key) + ": written only when true, got false");
      }
    if (t.held && t.reset) throw RecordingError(w.at("reset") + ": a held tick is not rendered, so not reset");
    parse_passivity(j, t, w);
  }
  r.ticks.push_back(t);
}

void parse_edit(const json& j, Recording& r, const Where& w) {
  only_keys(j, {"edit", "tick", "t", "brush"}, "", w);
  const json& kind = member(j, "edit", w);
  if (!kind.is_string()) throw RecordingError(w.at("edit") + ": must be a string, got " + shown(kind));
  EditEvent e;
  e.kind = edit_kind(kind.get<std::string>(), w);
  e.tick = integer(j, "tick", w);
  if (r.format_version >= 3) {
    const long prev = r.edits.empty() ? 0 : r.edits.back().tick;
    if (e.tick < prev)
      throw RecordingError(w.at("tick") + ": " + std::to_string(e.tick) + " is before the previous edit's tick " +
                           std::to_string(prev) + " (edits are in the order applied)");
  } else if (r.ticks.empty() || e.tick != long(r.ticks.size()) - 1)
    throw RecordingError(w.at("tick") + ": " + std::to_string(e.tick) + " is not the tick just before it (" +
                         (r.ticks.empty() ? std::string("none") : std::to_string(r.ticks.size() - 1)) +
                         "): edits follow their tick's line");
  e.t_s = member_number(j, "t", w);
  const auto b = j.find("brush");
  if (b != j.end()) e.brush = parse_brush(*b, w);
  else if (e.kind == EditEvent::Kind::kBrush) throw RecordingError(w.at("brush") + ": missing");
  if (e.kind == EditEvent::Kind::kBrush)
    if (const std::string bad = session::validate(e.brush); !bad.empty()) throw RecordingError(w.at("brush") + ": " + bad);
  r.edits.push_back(e);
}

void parse_end(const json& j, const Recording& r, const Where& w) {
  only_keys(j, {"end", "ticks", "edits"}, "", w);
  if (!boolean(j, "end", w)) throw RecordingError(w.at("end") + ": must be true");
  const long ticks = integer(j, "ticks", w), edits = integer(j, "edits", w);
  if (ticks != long(r.ticks.size()))
    throw RecordingError(w.at("ticks") + ": says " + std::to_string(ticks) + ", the file has " + std::to_string(r.ticks.size()));
  if (edits != long(r.edits.size()))
    throw RecordingError(w.at("edits") + ": says " + std::to_string(edits) + ", the file has " + std::to_string(r.edits.size()));
}

// ---------------------------------------------------------------- atomic write

std::string os_error(const std::string& path, const char* what) { return path + ": " + what + ": " + std::strerror(errno); }

/// Writes `content` through the one output writer (io/output_file.h): a crash leaves the
/// old file or the new one; a device, FIFO or "-" gets the text as a stream.
void write_atomically(const std::string& path, const std::string& content) {
  try {
    io::write_output(path, content);
  } catch (const io::OutputError& e) {
    throw RecordingError(path + ": not saved (the old file, if any, is untouched): " + e.what());
  }
}

}  // namespace

namespace {
std::string dump_line(const ojson& j) {
  // Strings are written with invalid UTF-8 replaced (U+FFFD): dump() would throw on it.
  return j.dump(-1, ' ', false, ojson::error_handler_t::replace) + '\n';
}
}  // namespace

std::string recording_header_line(const Recording& r, const std::string& name) {
  if (r.format_version < 1 || r.format_version > 3)
    throw RecordingError(name + ": field 'format_version': " + std::to_string(r.format_version) + " cannot be written (1, 2 or 3)");
  if (r.format_version >= 2 && !r.volume_crc32)
    throw RecordingError(name + ": field 'volume_crc32': format " + std::to_string(r.format_version) +
                         " needs the volume's checksum");
  if (!(r.rate_hz > 0) || !std::isfinite(r.rate_hz))
    throw RecordingError(name + ": field 'rate_hz': must be finite and > 0, got " + num(r.rate_hz));
  ojson header{{"format", kRecordingFormat},
               {"format_version", r.format_version},
               {"scene_path", r.scene_path},
               {"scene_text", r.scene_text},
               {"rate_hz", r.rate_hz}};
  if (r.format_version >= 2) header["volume_crc32"] = *r.volume_crc32;
  if (r.edit_session) {
    if (r.format_version < 3 || !(r.edit_session->history_limit_mib > 0) || !std::isfinite(r.edit_session->history_limit_mib))
      throw RecordingError(name + ": field 'edit_session': needs format 3 and a finite history_limit_mib > 0, got format " +
                           std::to_string(r.format_version) + ", " + num(r.edit_session->history_limit_mib) + " MiB");
    header["edit_session"] = {{"gpu_brushes", r.edit_session->gpu_brushes},
                              {"history_limit_mib", r.edit_session->history_limit_mib}};
    if (r.edit_session->edit_period_s > 0) header["edit_session"]["edit_period_s"] = r.edit_session->edit_period_s;
  }
  if ((r.isovalue || !r.history_restarts.empty()) && r.format_version < 3)
    throw RecordingError(name + ": fields 'isovalue' and 'history_restarts' (an edit journal's) need format 3, got format " +
                         std::to_string(r.format_version));
  if (r.isovalue) {
    if (!std::isfinite(r.isovalue->tau))
      throw RecordingError(name + ": field 'isovalue.tau': must be finite, got " + num(r.isovalue->tau));
    header["isovalue"] = {{"tau", r.isovalue->tau}, {"inside", core::to_string(r.isovalue->inside)}};
  }
  if (!r.history_restarts.empty()) {
    if (!std::is_sorted(r.history_restarts.begin(), r.history_restarts.end()))
      throw RecordingError(name + ": field 'history_restarts': must be ascending");
    header["history_restarts"] = r.history_restarts;
  }
  return dump_line(header);
}

std::string recording_tick_line(long k, const RecordedTick& t, int format_version, const std::string& name) {
  check_tick(t, std::size_t(k), name);
  ojson tick{{"k", k}, {"t", t.t_s}};
  if (format_version >= 3) {
    if (!(t.dt_s >= 0) || !(t.dt_s < 3600))
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field 'dt': must be in [0, 3600) s, got " + num(t.dt_s));
    tick["dt"] = t.dt_s;
  }
  tick["hip"] = vec_json(t.hip_m);
  tick["button"] = t.button;
  tick["force"] = vec_json(t.force_n);
  if (format_version >= 2) {
    if (t.version < 1)
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field 'version': must be >= 1, got 0");
    tick["vhip"] = vec_json(t.vhip_m);
    tick["version"] = t.version;
    if (t.fault) tick["fault"] = true;
  }
  if (t.held || t.reset) {
    const char* field = t.held ? "held" : "reset";
    if (format_version < 3)
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field '" + field + "': format " +
                           std::to_string(format_version) + " has no such field (3 has)");
    if (t.held && t.reset)
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field 'reset': a held tick is not rendered, so not reset");
    tick[field] = true;
  }
  if (t.passivity_clock_s) {
    const double pt = *t.passivity_clock_s;
    if (format_version < 3 || !(pt >= 0) || !(pt < 1e9) || !finite(t.sent_n) || t.held)
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field 'pt': needs format 3, a clock in [0, 1e9) s, " +
                           "a finite 'sent' and a tick that is not held, got format " + std::to_string(format_version) +
                           ", " + num(pt) + " s" + (t.held ? ", held" : ""));
    tick["pt"] = pt;
    tick["sent"] = vec_json(t.sent_n);
  }
  return dump_line(tick);
}

std::string recording_edit_line(const EditEvent& e, const std::string& name) {
  check_edit(e, 0, 0, std::numeric_limits<std::size_t>::max(), name);
  return dump_line(ojson{{"edit", to_string(e.kind)}, {"tick", e.tick}, {"t", e.t_s}, {"brush", brush_json(e.brush)}});
}

std::string recording_end_line(std::size_t ticks, std::size_t edits) {
  return dump_line(ojson{{"end", true}, {"ticks", ticks}, {"edits", edits}});
}

std::string recording_text(const Recording& r, const std::string& name) {
  std::string out = recording_header_line(r, name);
  for (std::size_t k = 1; k < r.ticks.size(); ++k)
    if (!(r.ticks[k].t_s > r.ticks[k - 1].t_s))
      throw RecordingError(name + ": tick " + std::to_string(k) + ": field 't': " + num(r.ticks[k].t_s) +
                           " s is not after the previous tick's " + num(r.ticks[k - 1].t_s) + " s");
  long prev = 0;
  const std::size_t edit_ticks = r.format_version >= 3 ? std::numeric_limits<std::size_t>::max() : r.ticks.size();
  for (std::size_t i = 0; i < r.edits.size(); ++i) {
    check_edit(r.edits[i], i, prev, edit_ticks, name);
    prev = r.edits[i].tick;
  }
  out.reserve(r.scene_text.size() + 160 * r.ticks.size() + 400 * r.edits.size() + 256);
  std::size_t e = 0;
  for (std::size_t k = 0; k < r.ticks.size(); ++k) {
    out += recording_tick_line(long(k), r.ticks[k], r.format_version, name);
    // Format 2: tick k's edits follow its line. Format 3: an edit follows the last tick
    // that ran before it was applied (tick = that count).
    const long upto = r.format_version >= 3 ? long(k) + 1 : long(k);
    for (; e < r.edits.size() && r.edits[e].tick <= upto; ++e) out += recording_edit_line(r.edits[e], name);
  }
  for (; e < r.edits.size(); ++e) out += recording_edit_line(r.edits[e], name);
  out += recording_end_line(r.ticks.size(), r.edits.size());
  return out;
}

Recording parse_recording(const std::string& content, const std::string& name, bool allow_incomplete) {
  Recording r;
  bool header = false, ended = false;
  std::size_t n = 0, pos = 0;
  while (pos < content.size()) {
    const std::size_t eol = content.find('\n', pos);
    const bool last = eol == std::string::npos;
    const std::string line = content.substr(pos, last ? std::string::npos : eol - pos);
    pos = last ? content.size() : eol + 1;
    ++n;
    if (ended) throw RecordingError(name + ": line " + std::to_string(n) + ": text after the end record");
    if (last && allow_incomplete && r.format_version >= 3) break;  // cut mid-line: drop the partial line
    if (last) throw RecordingError(name + ": line " + std::to_string(n) + ": truncated (the last line has no newline)");
    const json j = parse_line(line, name, n);
    if (!header) {
      parse_header(j, r, Where{name, n, "header"});
      header = true;
    } else if (j.contains("k")) {
      parse_tick(j, r, Where{name, n, "tick " + std::to_string(r.ticks.size())});
    } else if (j.contains("edit")) {
      parse_edit(j, r, Where{name, n, "edit " + std::to_string(r.edits.size())});
    } else if (j.contains("end")) {
      parse_end(j, r, Where{name, n, "end"});
      ended = true;
    } else {
      throw RecordingError(name + ": line " + std::to_string(n) + ": not a tick, edit or end record: " + shown(j));
    }
  }
  if (!header) throw RecordingError(name + ": empty: not a recording");
  if (!ended && allow_incomplete && r.format_version >= 3) {
    r.complete = false;
    return r;
  }
  if (!ended)
    throw RecordingError(name + ": truncated after line " + std::to_string(n) + " (" + std::to_string(r.ticks.size()) +
                         " ticks, " + std::to_string(r.edits.size()) + " edits read): no end record");
  return r;
}

std::string recorded_scene_path(const Recording& r, const std::string& recording_dir) {
  const std::filesystem::path p(r.scene_path);
  if (p.is_relative() && !recording_dir.empty()) return (std::filesystem::path(recording_dir) / p).string();
  return r.scene_path;
}

std::uint32_t volume_crc32(const engine::Volume& v) {
  uLong crc = ::crc32(0L, Z_NULL, 0);
  for (const int d : v.grid.dims) {
    const std::int32_t d32 = d;
    crc = ::crc32(crc, reinterpret_cast<const Bytef*>(&d32), sizeof d32);
  }
  const double geometry[15] = {v.grid.spacing_m.x, v.grid.spacing_m.y, v.grid.spacing_m.z, v.grid.origin_m.x,
                               v.grid.origin_m.y,  v.grid.origin_m.z,  v.direction[0],     v.direction[1],
                               v.direction[2],     v.direction[3],     v.direction[4],     v.direction[5],
                               v.direction[6],     v.direction[7],     v.direction[8]};
  crc = ::crc32(crc, reinterpret_cast<const Bytef*>(geometry), sizeof geometry);
  const auto* bytes = reinterpret_cast<const Bytef*>(v.voxels.data());
  std::size_t left = v.voxels.size() * sizeof(float);
  while (left > 0) {  // crc32 takes a uInt length
    const uInt n = uInt(std::min<std::size_t>(left, 1u << 30));
    crc = ::crc32(crc, bytes, n);
    bytes += n;
    left -= n;
  }
  return std::uint32_t(crc);
}

void save_recording(const std::string& path, const Recording& r) {
  write_atomically(path, recording_text(r, path));
}

Recording load_recording(const std::string& path, bool allow_incomplete) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw RecordingError(path + ": no such recording");
  if (const std::string no = not_a_regular_file(path); !no.empty())
    throw RecordingError(path + ": " + no + ": a recording is read from a regular file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RecordingError(os_error(path, "cannot open"));
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw RecordingError(os_error(path, "read failed"));
  return parse_recording(s.str(), path, allow_incomplete);
}

}  // namespace isotouch::io
