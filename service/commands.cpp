#include "isotouch/service/commands.h"

#include <cctype>
#include <cmath>
#include <sstream>
#include <vector>

namespace isotouch::service {
namespace {

std::vector<std::string> words(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> w;
  for (std::string s; in >> s;) w.push_back(s);
  return w;
}

/// `s` as a finite number, or why not ("isovalue 'abc': not a number").
std::variant<double, std::string> number(const std::string& what, const std::string& s) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty()) return what + " '" + s + "': not a number";
  if (!std::isfinite(v)) return what + " '" + s + "': not finite";
  return v;
}

std::string shown(const std::string& s) {
  std::string o;
  for (char c : s.substr(0, 64)) o += (c >= 32 && c < 127) ? c : '?';
  return o;
}

std::variant<Command, std::string> parse_tool(const std::vector<std::string>& w) {
  Command c;
  c.kind = Command::Kind::kTool;
  if (w.size() < 2 || w.size() > 4) return "tool: expected 'tool KIND [RADIUS_MM [STRENGTH]]', got " + std::to_string(w.size() - 1) + " values";
  c.tool = w[1];
  if (c.tool != "add" && c.tool != "carve" && c.tool != "smooth" && c.tool != "drill")
    return "tool kind '" + shown(c.tool) + "': not add, carve, smooth or drill";
  if (w.size() > 2) {
    auto r = number("tool radius", w[2]);
    if (auto* e = std::get_if<std::string>(&r)) return *e;
    c.radius_mm = std::get<double>(r);
    if (!(c.radius_mm >= 0.1 && c.radius_mm <= 100)) return "tool radius '" + w[2] + "': not within [0.1, 100] mm";
  }
  if (w.size() > 3) {
    auto r = number("tool strength", w[3]);
    if (auto* e = std::get_if<std::string>(&r)) return *e;
    c.strength = std::get<double>(r);
    if (!(c.strength > 0)) return "tool strength '" + w[3] + "': not positive";
    if (c.tool == "smooth" && c.strength > 1) return "tool strength '" + w[3] + "': smooth takes (0, 1]";
  }
  return c;
}

std::variant<Command, std::string> parse_save(const std::vector<std::string>& w) {
  if (w.size() != 2) return "save: expected 'save NAME', got " + std::to_string(w.size() - 1) + " values";
  const std::string& f = w[1];
  bool plain = !f.empty() && f[0] != '.' && f.size() <= 200;
  for (char ch : f) plain = plain && (std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-');
  if (!plain) return "save name '" + shown(f) + "': a file name of letters, digits, '.', '_', '-' (no folder, not starting with '.')";
  Command c;
  c.kind = Command::Kind::kSave;
  c.file = f;
  return c;
}

}  // namespace

std::variant<Command, std::string> parse_command(const std::string& text) {
  const std::vector<std::string> w = words(text);
  if (w.empty()) return std::string("empty command (commands: isovalue, tool, apply, stop, undo, redo, save)");
  const std::string& verb = w[0];
  Command c;
  if (verb == "isovalue") {
    if (w.size() != 2) return "isovalue: expected 'isovalue V', got " + std::to_string(w.size() - 1) + " values";
    auto r = number("isovalue", w[1]);
    if (auto* e = std::get_if<std::string>(&r)) return *e;
    c.kind = Command::Kind::kIsovalue;
    c.value = std::get<double>(r);
    return c;
  }
  if (verb == "tool") return parse_tool(w);
  if (verb == "save") return parse_save(w);
  using K = Command::Kind;
  const std::pair<const char*, K> bare[] = {{"apply", K::kApply}, {"stop", K::kStop}, {"undo", K::kUndo}, {"redo", K::kRedo}};
  for (const auto& [name, kind] : bare)
    if (verb == name) {
      if (w.size() != 1) return verb + ": takes no value, got '" + shown(w[1]) + "'";
      c.kind = kind;
      return c;
    }
  return "unknown command '" + shown(verb) + "' (commands: isovalue, tool, apply, stop, undo, redo, save)";
}

std::string to_string(const Command& c) {
  std::ostringstream s;
  using K = Command::Kind;
  switch (c.kind) {
    case K::kIsovalue: s << "isovalue " << c.value; break;
    case K::kTool:
      s << "tool " << c.tool;
      if (c.radius_mm > 0) s << " " << c.radius_mm;
      if (c.strength > 0) s << " " << c.strength;
      break;
    case K::kApply: s << "apply"; break;
    case K::kStop: s << "stop"; break;
    case K::kUndo: s << "undo"; break;
    case K::kRedo: s << "redo"; break;
    case K::kSave: s << "save " << c.file; break;
  }
  return s.str();
}

}  // namespace isotouch::service
