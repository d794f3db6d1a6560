// commands.h - the STRING commands `isotouch serve` takes (docs/slicer.md has the grammar):
//   isovalue V                       the session's isovalue [value units]
//   tool KIND [RADIUS_MM [STRENGTH]] the tool: add, carve, smooth or drill; radius [mm];
//                                    strength as the scene's edits.brush (add/carve: value
//                                    units per application, smooth: (0, 1], drill: rate
//                                    [value units / (N s)])
//   apply | stop                     start / stop applying the tool at the proxy while in contact
//   undo | redo                      one stroke back / forward
//   save NAME                        the edited volume to NAME in the server's save folder (a
//                                    plain file name; its format is checked where it is written)
// Words are separated by spaces; case matters. Parsing needs no session: the values that
// depend on one (the isovalue's range) are checked where the command runs.
// Part of isotouch::service.
#pragma once
#include <string>
#include <variant>

namespace isotouch::service {

struct Command {
  enum class Kind { kIsovalue, kTool, kApply, kStop, kUndo, kRedo, kSave };
  Kind kind = Kind::kApply;
  double value = 0;         ///< kIsovalue [value units]
  std::string tool;         ///< kTool: "add", "carve", "smooth", "drill"
  double radius_mm = -1;    ///< kTool: > 0, or < 0 = unchanged
  double strength = -1;     ///< kTool: > 0, or < 0 = unchanged
  std::string file;         ///< kSave: a file name (no folder part)
};

/// The command `text` says, or (the string alternative) why not, naming the command and
/// the offending value ("tool radius 'x': not a number").
std::variant<Command, std::string> parse_command(const std::string& text);

/// The command as text (for STATUS replies and the log): "isovalue 500", "tool carve 3 100", ...
std::string to_string(const Command& c);

}  // namespace isotouch::service
