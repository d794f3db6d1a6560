// iso_panel.h - the isovalue's part of the tool panel: the volume's histogram with the
// isovalue marked on it (drag on it to move the isovalue; letting go restarts the session
// at it, as the slider does) and the presets (CT in HU), and what fills them.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "isotouch/apps/sculpt/overlay.h"
#include "isotouch/engine/iso_choice.h"
#include "isotouch/engine/volume.h"

namespace isotouch::sculpt {

/// The panel's histogram of `vol` (log(1 + count), 128 bins over its range) and its presets:
/// `choice`'s, else the CT presets when the volume is CT in HU by its minimum, else none.
void fill_iso_panel(IsoControl& iso, const engine::Volume& vol, const std::optional<engine::IsoChoice>& choice);

/// The preset called `name` in `iso`, if any.
std::optional<double> preset_value(const IsoControl& iso, const std::string& name);

/// Draws the histogram (the isovalue as a line on it, draggable) and the preset buttons into
/// the current ImGui window; sets iso.value and iso.committed as the slider does.
void iso_histogram_widgets(IsoControl& iso);

}  // namespace isotouch::sculpt
