#include "isotouch/apps/sculpt/input_script.h"

#include <GLFW/glfw3.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "isotouch/io/scene_field_range.h"

namespace isotouch::sculpt {

namespace {

using json = nlohmann::json;

int key_code(const std::string& k) {
  if (k.size() == 1) {
    const char c = k[0];
    if (c >= 'a' && c <= 'z') return GLFW_KEY_A + (c - 'a');
    if (c >= 'A' && c <= 'Z') return GLFW_KEY_A + (c - 'A');
    if (c >= '0' && c <= '9') return GLFW_KEY_0 + (c - '0');
    if (c == '[') return GLFW_KEY_LEFT_BRACKET;
    if (c == ']') return GLFW_KEY_RIGHT_BRACKET;
    if (c == '-') return GLFW_KEY_MINUS;
    if (c == '=') return GLFW_KEY_EQUAL;
    if (c == ',') return GLFW_KEY_COMMA;
    if (c == '.') return GLFW_KEY_PERIOD;
  }
  if (k == "left") return GLFW_KEY_LEFT;
  if (k == "right") return GLFW_KEY_RIGHT;
  if (k == "up") return GLFW_KEY_UP;
  if (k == "down") return GLFW_KEY_DOWN;
  if (k == "pageup") return GLFW_KEY_PAGE_UP;
  if (k == "pagedown") return GLFW_KEY_PAGE_DOWN;
  if (k == "escape") return GLFW_KEY_ESCAPE;
  return -1;
}

const ScriptKey* script_key(const std::string& k) {
  for (const ScriptKey& s : kScriptKeys)
    if (s.name == k) return &s;
  return nullptr;
}

/// The numeric default of `key` in kScriptKeys.
double script_default(std::string_view key) {
  for (const ScriptKey& s : kScriptKeys)
    if (s.name == key) return io::plain_number(s.default_text).value();
  return 0;
}

/// "cursor, press, ...": the actions, for messages.
std::string action_names() {
  std::string list;
  for (const ScriptKey& s : kScriptKeys)
    if (s.action) list += (list.empty() ? "" : ", ") + std::string(s.name);
  return list;
}

}  // namespace

std::vector<InputEvent> parse_input_script(const std::string& text, const std::string& name) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw ScriptError(name + ": not JSON: " + e.what());
  }
  if (!j.is_object() || !j.contains("events") || !j["events"].is_array())
    throw ScriptError(name + ": expected {\"events\": [...]}");
  std::vector<InputEvent> out;
  const json& evs = j["events"];
  for (std::size_t i = 0; i < evs.size(); ++i) {
    const json& e = evs[i];
    const std::string at = name + ": event " + std::to_string(i);
    auto fail = [&](const std::string& why) { throw ScriptError(at + ": " + why); };
    if (!e.is_object()) fail("not an object");
    InputEvent ev;
    ev.after_frames = int(script_default("after_frames"));
    ev.timeout_s = script_default("timeout_s");
    auto num = [&](const json& v, const char* field) {
      if (!v.is_number()) fail(std::string("field '") + field + "' must be a number, got " + v.dump());
      const double d = v.get<double>();
      if (!std::isfinite(d)) fail(std::string("field '") + field + "' is not finite");
      const auto range = io::field_range(script_key(field)->range);
      if (range && !range->contains(d)) fail(std::string("field '") + field + "' must be " + range->phrase() + ", got " + v.dump());
      return d;
    };
    auto pair = [&](const json& v, const char* field) {
      if (!v.is_array() || v.size() != 2) fail(std::string("field '") + field + "' must be [a, b], got " + v.dump());
      return std::array<double, 2>{num(v[0], field), num(v[1], field)};
    };
    auto button = [&](const json& v, const char* field) {
      const std::string b = v.is_string() ? v.get<std::string>() : "";
      if (b == "left") return 0;
      if (b == "right") return 1;
      if (b == "middle") return 2;
      fail(std::string("field '") + field + "' must be \"left\", \"right\" or \"middle\", got " + v.dump());
      return 0;
    };
    int actions = 0;
    using K = InputEvent::Kind;
    for (const auto& [k, v] : e.items()) {
      const ScriptKey* key = script_key(k);
      if (!key) fail("unknown field '" + k + "'");
      actions += key->action;
      if (k == "after_frames") {
        ev.after_frames = int(num(v, "after_frames"));
      } else if (k == "mods") {
        if (!v.is_array()) fail("field 'mods' must be a list of \"ctrl\" / \"shift\"");
        for (const json& m : v) {
          if (m == "ctrl") ev.ctrl = true;
          else if (m == "shift") ev.shift = true;
          else fail("field 'mods': unknown modifier " + m.dump());
        }
      } else if (k == "radius_mm") {
        ev.radius_mm = num(v, "radius_mm");
      } else if (k == "strength") {
        ev.strength = num(v, "strength");
      } else if (k == "timeout_s") {
        ev.timeout_s = num(v, "timeout_s");
      } else {
        if (k == "cursor") {
          ev.kind = K::kCursor;
          ev.xy = pair(v, "cursor");
        } else if (k == "press" || k == "release") {
          ev.kind = k == "press" ? K::kPress : K::kRelease;
          ev.button = button(v, k.c_str());
        } else if (k == "scroll") {
          ev.kind = K::kScroll;
          ev.xy[0] = num(v, "scroll");
        } else if (k == "key") {
          ev.kind = K::kKey;
          ev.key = v.is_string() ? key_code(v.get<std::string>()) : -1;
          if (ev.key < 0) fail("field 'key': unknown key " + v.dump());
        } else if (k == "tool") {
          ev.kind = K::kTool;
          ev.text = v.is_string() ? v.get<std::string>() : "";
          if (ev.text != "add" && ev.text != "carve" && ev.text != "smooth" && ev.text != "drill")
            fail("field 'tool' must be add, carve, smooth or drill, got " + v.dump());
        } else if (k == "orbit") {
          ev.kind = K::kOrbit;
          ev.xy = pair(v, "orbit");
        } else if (k == "zoom") {
          ev.kind = K::kZoom;
          ev.xy[0] = num(v, "zoom");
        } else if (k == "wait") {
          ev.kind = K::kWait;
          ev.text = v.is_string() ? v.get<std::string>() : "";
          if (ev.text != "contact" && ev.text != "edits" && ev.text != "change")
            fail("field 'wait' must be \"contact\", \"edits\" or \"change\", got " + v.dump());
        } else if (k == "screenshot") {
          ev.kind = K::kScreenshot;
          ev.text = v.is_string() ? v.get<std::string>() : "";
          if (ev.text.empty() || ev.text.find('/') != std::string::npos)
            fail("field 'screenshot' must be a file name without folders, got " + v.dump());
        } else if (k == "resize") {
          ev.kind = K::kResize;
          ev.xy = pair(v, "resize");
        } else if (k == "drop") {
          ev.kind = K::kDrop;
          ev.text = v.is_string() ? v.get<std::string>() : "";
          if (ev.text.empty()) fail("field 'drop' must be a file name, got " + v.dump());
        } else if (k == "preset") {
          ev.kind = K::kPreset;
          ev.text = v.is_string() ? v.get<std::string>() : "";
          if (ev.text.empty()) fail("field 'preset' must be a preset's name, got " + v.dump());
        } else if (k == "iso") {
          ev.kind = K::kIso;
          ev.xy[0] = num(v, "iso");
        } else if (k == "quit") {
          ev.kind = K::kQuit;
        } else {
          fail("unknown field '" + k + "'");
        }
      }
    }
    if (actions != 1) fail("needs exactly one action (" + action_names() + "), got " + std::to_string(actions));
    out.push_back(ev);
  }
  return out;
}

std::vector<InputEvent> load_input_script(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ScriptError(path + ": cannot read the input script");
  std::ostringstream s;
  s << in.rdbuf();
  std::vector<InputEvent> evs = parse_input_script(s.str(), path);
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  for (InputEvent& e : evs)
    if (e.kind == InputEvent::Kind::kDrop && std::filesystem::path(e.text).is_relative()) e.text = (dir / e.text).string();
  return evs;
}

}  // namespace isotouch::sculpt
