#include "isotouch/apps/sculpt/iso_panel.h"

#include <algorithm>
#include <cfloat>
#include <cmath>

#if ISOTOUCH_WITH_IMGUI
#include <imgui.h>
#endif

namespace isotouch::sculpt {

void fill_iso_panel(IsoControl& iso, const engine::Volume& vol, const std::optional<engine::IsoChoice>& choice) {
  const engine::Histogram h = engine::histogram(vol, 128);
  iso.histogram.clear();
  for (std::uint64_t c : h.counts) iso.histogram.push_back(float(std::log1p(double(c))));
  iso.presets.clear();
  const std::vector<engine::IsoPreset> presets =
      choice ? choice->presets : engine::is_ct_hounsfield(vol, "") ? engine::ct_hu_presets() : std::vector<engine::IsoPreset>{};
  for (const auto& p : presets)
    if (p.value > vol.min_value && p.value < vol.max_value) iso.presets.emplace_back(p.name, p.value);
}

std::optional<double> preset_value(const IsoControl& iso, const std::string& name) {
  for (const auto& [n, v] : iso.presets)
    if (n == name) return v;
  return std::nullopt;
}

#if ISOTOUCH_WITH_IMGUI
void iso_histogram_widgets(IsoControl& iso) {
  if (!iso.histogram.empty() && iso.hi > iso.lo) {
    const ImVec2 size(ImGui::CalcItemWidth(), 60);
    const ImVec2 at = ImGui::GetCursorScreenPos();
    ImGui::PlotHistogram("##histogram", iso.histogram.data(), int(iso.histogram.size()), 0, nullptr, 0.0f, FLT_MAX, size);
    // The isovalue on it, and a drag over it that moves it.
    ImGui::SetCursorScreenPos(at);
    ImGui::InvisibleButton("##histogram-drag", size);
    if (ImGui::IsItemActive()) {
      const double f = std::clamp((ImGui::GetIO().MousePos.x - at.x) / size.x, 0.0f, 1.0f);
      iso.value = iso.lo + f * (iso.hi - iso.lo);
    }
    if (ImGui::IsItemDeactivated()) {
      iso.committed = true;
      iso.how = "hand (the histogram)";
    }
    const float x = at.x + float((iso.value - iso.lo) / (iso.hi - iso.lo)) * size.x;
    ImGui::GetWindowDrawList()->AddLine(ImVec2(x, at.y), ImVec2(x, at.y + size.y), IM_COL32(255, 80, 60, 255), 2.0f);
    ImGui::SameLine();
    ImGui::TextUnformatted("histogram (log)");
  }
  for (std::size_t i = 0; i < iso.presets.size(); ++i) {
    if (i > 0) ImGui::SameLine();
    if (ImGui::Button(iso.presets[i].first.c_str())) {
      iso.value = iso.presets[i].second;
      iso.committed = true;
      iso.how = "the preset " + iso.presets[i].first;
    }
  }
}
#endif

}  // namespace isotouch::sculpt
