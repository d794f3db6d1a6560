// input_script.h - input events that drive the sculpting window without a person.
//
// FILE (JSON): {"events": [EVENT, ...]}, run in order. Each EVENT is one object with
// "after_frames": N (frames drawn after the previous event before this one; default 1) and
// exactly one action:
//   {"cursor": [fx, fy]}           the cursor at fractions of the framebuffer (0..1, y down)
//   {"press": "left"|"right"|"middle"} / {"release": ...}
//   {"scroll": dy}                 the wheel (probe depth; with "mods": ["ctrl"]: zoom)
//   {"key": "Z", "mods": ["ctrl", "shift"]}   a key press (letters, digits, "[", "]", "-",
//                                  "=", "left", "right", "up", "down", "pageup", "pagedown", "escape")
//   {"tool": "carve", "radius_mm": 6, "strength": 0.3}   tool change (radius, strength optional)
//   {"orbit": [d_azimuth_deg, d_elevation_deg]}, {"zoom": factor}
//   {"wait": "contact" | "edits" | "change", "timeout_s": 10}   hold the script until the
//                                  probe is in contact / every submitted edit is applied and
//                                  drawn / a brush that changed voxels was drawn after the wait began
//   {"screenshot": "NAME.png"}     the frame as drawn, into the --screenshot folder (or ".")
//   {"drop": "FILE"}               a file dropped on the window (relative to the script's folder)
//   {"preset": "bone"}             the isovalue preset button of that name (CT in HU: bone,
//                                  soft tissue / skin, lung): as "iso" at its value
//   {"iso": value}                 the isovalue slider let go at `value` (the session restarts
//                                  at it with the edited volume; the script goes on there)
//   {"resize": [w, h]}, {"quit": true}
#pragma once
#include <array>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace isotouch::sculpt {

/// An event's keys, in one table: the parser accepts exactly these (an action is the one thing
/// an event does; the rest qualify it), checks each number against `range` and takes a
/// plain-number `default_text` as the default; docs/user-guide.md's two Input scripts tables
/// list exactly these with the same unit, range and default (the fields table) and range
/// (the actions table, each number of the value; tests/test_input_script.cpp reads both).
/// A range is written as io/scene_field_range.h reads it ("> 0", "integer [0, 1e7]"); "any"
/// and "-" check nothing.
struct ScriptKey {
  std::string_view name;
  bool action;
  std::string_view unit, range, default_text;
};
inline constexpr ScriptKey kScriptKeys[] = {
    {"after_frames", false, "frames", "integer [0, 1e7]", "1"},
    {"mods", false, "", "list of `\"ctrl\"`, `\"shift\"`", "none"},
    {"radius_mm", false, "mm", "> 0", "unchanged"},
    {"strength", false, "as the Tool panel's", ">= 0", "unchanged"},
    {"timeout_s", false, "s", "> 0", "10"},
    {"cursor", true, "", "[0, 1]", ""}, {"press", true, "", "-", ""}, {"release", true, "", "-", ""},
    {"scroll", true, "", "any", ""}, {"key", true, "", "-", ""}, {"tool", true, "", "-", ""},
    {"orbit", true, "", "any", ""}, {"zoom", true, "", "> 0", ""}, {"wait", true, "", "-", ""},
    {"screenshot", true, "", "-", ""}, {"drop", true, "", "-", ""}, {"iso", true, "", "any", ""},
    {"preset", true, "", "-", ""}, {"resize", true, "", "[1, 8192]", ""}, {"quit", true, "", "-", ""},
};

struct ScriptError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct InputEvent {
  enum class Kind { kCursor, kPress, kRelease, kScroll, kKey, kTool, kOrbit, kZoom, kWait, kScreenshot, kResize, kQuit, kDrop, kIso, kPreset };
  Kind kind = Kind::kQuit;
  int after_frames = 1;
  std::array<double, 2> xy{0, 0};  ///< cursor fractions, orbit degrees, resize pixels, scroll (x: dy), isovalue (x)
  int button = 0;                  ///< 0 left, 1 right, 2 middle
  int key = 0;                     ///< GLFW key code
  bool ctrl = false, shift = false;
  std::string text;                ///< tool name, wait condition, screenshot name, dropped file
  double radius_mm = -1, strength = -1;  ///< -1: unchanged
  double timeout_s = 10;                 ///< kScriptKeys' default (the parser sets it)
};

/// Parses a script's text; `name` is used in messages. @throws ScriptError naming the file,
/// the event's index and the field and value.
std::vector<InputEvent> parse_input_script(const std::string& text, const std::string& name);
/// Reads and parses FILE. @throws ScriptError (also when it cannot be read).
std::vector<InputEvent> load_input_script(const std::string& path);

}  // namespace isotouch::sculpt
