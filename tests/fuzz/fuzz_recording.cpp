// libFuzzer target for the recording parser: any input either parses or throws
// RecordingError; what parses can be written back and parses to the same text, and the scene
// text it carries (what replay runs) either parses or throws SceneError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "isotouch/io/record.h"
#include "isotouch/io/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const bool allow_incomplete = data[0] & 1;  // the first byte picks the mode, the rest is the file
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    const isotouch::io::Recording r = isotouch::io::parse_recording(text, "fuzz.rec", allow_incomplete);
    if (!allow_incomplete && !r.complete) __builtin_trap();
    if (r.complete) {
      // Whatever loads is a recording the writer accepts, and a fixed point of write + read.
      const std::string again = isotouch::io::recording_text(r, "fuzz.rec");
      if (isotouch::io::recording_text(isotouch::io::parse_recording(again, "again.rec"), "again.rec") != again)
        __builtin_trap();
    }
    try {
      (void)isotouch::io::parse_scene(r.scene_text, isotouch::io::recorded_scene_path(r, "/fuzz"));
    } catch (const isotouch::io::SceneError&) {
    }
  } catch (const isotouch::io::RecordingError&) {
  }
  return 0;
}
