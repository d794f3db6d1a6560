#include "isotouch/engine/iso_choice.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

namespace isotouch::engine {

namespace {
/// "%.6g" of a value, for the rule's text.
std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

/// Prefix sums of a histogram's counts and of count x bin centre: a run of bins' n and
/// sum in O(1).
struct Prefix {
  std::vector<double> n, s;
  explicit Prefix(const Histogram& h) : n(h.counts.size() + 1, 0.0), s(h.counts.size() + 1, 0.0) {
    for (std::size_t i = 0; i < h.counts.size(); ++i) {
      n[i + 1] = n[i] + double(h.counts[i]);
      s[i + 1] = s[i] + double(h.counts[i]) * h.bin_centre(i);
    }
  }
  /// n mu^2 of bins [a, b): a class's share of the between-class variance (times N).
  double term(std::size_t a, std::size_t b) const {
    const double c = n[b] - n[a];
    return c > 0 ? (s[b] - s[a]) * (s[b] - s[a]) / c : 0.0;
  }
};
}  // namespace

Histogram histogram(const Volume& vol, std::size_t bins) {
  Histogram h;
  if (vol.finite_voxels == 0 || bins == 0) return h;
  h.lo = vol.min_value;
  h.hi = vol.max_value;
  h.counts.assign(h.hi > h.lo ? bins : 1, 0);
  const double scale = h.hi > h.lo ? double(h.counts.size()) / (h.hi - h.lo) : 0.0;
  const std::size_t last = h.counts.size() - 1;
  for (float v : vol.voxels) {
    if (!std::isfinite(v)) continue;
    const double f = (double(v) - h.lo) * scale;
    ++h.counts[f >= double(last) ? last : std::size_t(f > 0 ? f : 0)];
  }
  return h;
}

std::vector<double> otsu_thresholds(const Histogram& h, int classes) {
  const std::size_t L = h.counts.size();
  if ((classes != 2 && classes != 3) || L < std::size_t(classes)) return {};
  const Prefix p(h);
  double best = -1;
  std::size_t b1 = 1, b2 = L;
  if (classes == 2) {
    for (std::size_t t = 1; t < L; ++t)
      if (const double v = p.term(0, t) + p.term(t, L); v > best) best = v, b1 = t;
    return {h.bin_edge(b1)};
  }
  for (std::size_t t1 = 1; t1 + 1 < L; ++t1)
    for (std::size_t t2 = t1 + 1; t2 < L; ++t2)
      if (const double v = p.term(0, t1) + p.term(t1, t2) + p.term(t2, L); v > best) best = v, b1 = t1, b2 = t2;
  return {h.bin_edge(b1), h.bin_edge(b2)};
}

const std::vector<IsoPreset>& ct_hu_presets() {
  static const std::vector<IsoPreset> presets{
      {"bone", 300, 150, 500}, {"soft tissue / skin", -300, -500, -100}, {"lung", -700, -900, -500}};
  return presets;
}

std::string hu_by_histogram(const Volume& vol) {
  if (vol.finite_voxels == 0 || vol.min_value < -3100 || vol.max_value < 300) return "";
  std::uint64_t n = 0, air = 0, soft = 0, bone = 0;
  for (const float v : vol.voxels) {
    if (!std::isfinite(v)) continue;
    ++n;
    air += v >= -1100 && v <= -850;
    soft += v >= -150 && v <= 150;
    bone += v >= 300 && v <= 3100;
  }
  const double fa = double(air) / double(n), fs = double(soft) / double(n), fb = double(bone) / double(n);
  if (fa < 0.01 || fs < 0.02 || fb < 0.0005) return "";
  const auto pct = [](double f) { return num(std::round(f * 1000) / 10) + " %"; };
  return "histogram: air " + pct(fa) + " in -1100 to -850, soft tissue " + pct(fs) + " in -150 to 150, bone " +
         pct(fb) + " in 300 to 3100";
}

bool is_ct_hounsfield(const Volume& vol, const VolumeHints& hints, std::string* why) {
  std::string reason;
  // Free text in a header is a claim the values must bear out: air below -500.
  const bool air = vol.finite_voxels > 0 && vol.min_value < -500;
  if (hints.modality == "CT" && (hints.modality_from.empty() || air))
    reason = hints.modality_from.empty() ? "modality CT" : hints.modality_from;
  else if (hints.units == "HU" && air)
    reason = hints.units_from;
  else if (vol.finite_voxels > 0 && std::abs(double(vol.min_value) + 1024.0) <= 100.0)
    reason = "minimum " + num(vol.min_value) + ", air in HU";
  else if (hints.modality.empty() || hints.modality == "CT")  // an MR's histogram is not asked
    reason = hu_by_histogram(vol);
  if (why) *why = reason;
  return !reason.empty();
}

bool is_ct_hounsfield(const Volume& vol, const std::string& modality, std::string* why) {
  VolumeHints h;
  h.modality = modality;
  return is_ct_hounsfield(vol, h, why);
}

IsoChoice choose_isovalue(const Volume& vol, const VolumeHints& hints) {
  IsoChoice c;
  if (hints.stored) {
    c.iso = *hints.stored;
    c.rule = "stored in the file (" + hints.stored_from + "): " + num(c.iso.tau) + ", inside " +
             core::to_string(c.iso.inside);
    return c;
  }
  const double lo = vol.min_value, hi = vol.max_value;
  if (vol.finite_voxels == 0 || !(hi > lo)) {
    c.iso.tau = vol.finite_voxels == 0 ? 0.0 : lo;
    c.rule = vol.finite_voxels == 0 ? "no finite voxels: 0" : "a constant volume (" + num(lo) + "): no isosurface";
    return c;
  }
  std::string why;
  if (is_ct_hounsfield(vol, hints, &why)) {
    c.hounsfield = true;
    c.presets = ct_hu_presets();
    const IsoPreset& bone = c.presets.front();
    c.iso.tau = bone.value;
    c.rule = "CT in HU (" + why + "): bone preset " + num(bone.value) + " HU (band " + num(bone.band_lo) + " to " +
             num(bone.band_hi) + ")";
    return c;
  }
  const Histogram h = histogram(vol, 256);
  const std::vector<double> t = otsu_thresholds(h, 3);
  c.iso.tau = t.size() == 2 ? t[1] : 0.5 * (lo + hi);
  c.rule = "histogram: upper threshold of a three-class Otsu (256 bins over " + num(lo) + " to " + num(hi) +
           "; lower threshold " + num(t.empty() ? lo : t[0]) + "): " + num(c.iso.tau);
  return c;
}

std::string iso_line(const IsoChoice& c) {
  return "isovalue " + num(c.iso.tau) + " (inside " + core::to_string(c.iso.inside) + "), chosen by " + c.rule;
}

}  // namespace isotouch::engine
