// record.cpp - STUB (lead) until the record-replay helper fills it in.
#include "record.h"

namespace isotouch::app {

void save_recording(const std::string& path, const Recording&) {
  throw RecordingError(path + ": recording is not implemented yet");
}
Recording load_recording(const std::string& path) {
  throw RecordingError(path + ": recording is not implemented yet");
}

}  // namespace isotouch::app
