// scan_input.h - a volume opened without --iso: loaded with its header's hints and opened at
// the isovalue they choose (engine/iso_choice.h), the rule said.
#pragma once
#include <string>

#include "isotouch/engine/iso_choice.h"
#include "isotouch/engine/volume.h"

namespace isotouch::sculpt {

/// A volume and the isovalue it opens at.
struct ScanInput {
  engine::Volume volume;
  engine::IsoChoice choice;
};

/// Loads a volume file or DICOM folder (io::load_scan) and chooses its isovalue.
/// @throws what the loaders throw, naming the file.
ScanInput open_scan(const std::string& path);

/// True for a scene file (.json), false for a volume.
bool is_scene_path(const std::string& path);

}  // namespace isotouch::sculpt
