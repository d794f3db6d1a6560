// iso_choice.h - the isovalue a volume opens at when none is given, and the rule that chose
// it: the isovalue its file stores; bone for CT in Hounsfield units (with presets for bone,
// soft tissue / skin and lung); else the upper threshold of a three-class Otsu on its
// histogram (air or background / soft material / dense material: bone on a CT that is not in
// HU, metal on an industrial CT; a two-class Otsu lands between air and skin).
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

/// Counts of a volume's finite voxels in equal bins over [lo, hi] (value units). Bin i holds
/// values in [lo + i w, lo + (i + 1) w), the last one also hi; w = (hi - lo) / bins.
struct Histogram {
  double lo = 0, hi = 0;
  std::vector<std::uint64_t> counts;
  double bin_width() const { return counts.empty() ? 0 : (hi - lo) / double(counts.size()); }
  double bin_centre(std::size_t i) const { return lo + (double(i) + 0.5) * bin_width(); }
  /// Lower edge of bin i [value units].
  double bin_edge(std::size_t i) const { return lo + double(i) * bin_width(); }
};

/// The histogram of `vol`'s finite voxels over [min_value, max_value] (Volume::update_stats
/// must be current). A constant volume gives one full bin; none finite gives no counts.
Histogram histogram(const Volume& vol, std::size_t bins = 256);

/// Otsu's thresholds on a histogram: the bin edges that split it into `classes` (2 or 3)
/// runs of bins maximising the between-class variance (sum over classes of n_k mu_k^2, with
/// each bin's voxels at its centre). Exhaustive over every split. @return the thresholds,
/// ascending, in value units (the lower edge of each class after the first); empty when the
/// histogram has fewer than `classes` bins.
std::vector<double> otsu_thresholds(const Histogram& h, int classes);

/// One isovalue a user picks by name (CT in HU): `value` is what it opens at, in a band of
/// values that show the same tissue.
struct IsoPreset {
  std::string name;       ///< "bone", "soft tissue / skin", "lung"
  double value = 0;       ///< [HU]
  double band_lo = 0, band_hi = 0;  ///< [HU]
};

/// The CT presets in HU: bone 300 (150-500), soft tissue / skin -300 (-500 to -100: the
/// body's surface against air), lung -700 (-900 to -500: vessels and airway walls inside the
/// lung). The first is the default.
const std::vector<IsoPreset>& ct_hu_presets();

/// What a file says about its data beyond the voxels (io::load_scan fills it).
struct VolumeHints {
  std::string modality;                  ///< DICOM (0008,0060) or MetaImage `Modality` as "CT", "MR"; "" unknown
  /// Where `modality` came from when a header's free text said it (a NIfTI `descrip`, a NRRD
  /// `content`: "NIfTI descrip 'CT abdomen'"); "" when a modality field said it. Free text
  /// counts as CT in HU only where the values agree (air: a minimum below -500).
  std::string modality_from;
  std::string units;                     ///< "HU" when a header's text says Hounsfield units; "" unknown
  std::string units_from;                ///< where `units` came from, as `modality_from`
  std::optional<core::Isosurface> stored;  ///< an isovalue the file stores (a .vdb's metadata, a level set)
  std::string stored_from;               ///< where `stored` came from, e.g. ".vdb metadata isotouch_isovalue"
};

/// The isovalue chosen and why.
struct IsoChoice {
  core::Isosurface iso;
  std::string rule;                  ///< one line: the rule and its inputs, e.g. "CT in HU (min -1024 HU): bone preset 300 HU"
  bool hounsfield = false;           ///< the volume was taken to be CT in HU
  std::vector<IsoPreset> presets;    ///< CT in HU: ct_hu_presets(); empty otherwise
};

/// True when `vol` is taken to be CT in Hounsfield units, by the first of: `hints.modality`
/// "CT" (DICOM CT pixels are rescaled to HU on loading; a MetaImage says MET_MOD_CT; free
/// text only with a minimum below -500); `hints.units` "HU" (the same condition); the smallest
/// finite value within 100 of -1024 (air in a CT stored as HU); the histogram (hu_by_histogram;
/// not for another modality).
/// `why` gets the reason, for the rule.
bool is_ct_hounsfield(const Volume& vol, const VolumeHints& hints, std::string* why = nullptr);
/// The same with only a modality known ("" for none).
bool is_ct_hounsfield(const Volume& vol, const std::string& modality, std::string* why = nullptr);

/// The histogram's evidence of CT in HU, for scans whose header says nothing and whose
/// minimum is not air's -1024 (a resampled or cropped CT): at least 1 % of the finite voxels
/// in air's band [-1100, -850], 2 % in soft tissue's [-150, 150] and 0.05 % in a bone tail
/// [300, 3100], and nothing below -3100 (a scanner's padding is -3024 at the lowest).
/// @return the reason ("air 31 % near -1000, soft tissue ..."), or "" when it does not hold.
std::string hu_by_histogram(const Volume& vol);

/// The isovalue `vol` opens at: (1) `hints.stored`; (2) CT in HU (is_ct_hounsfield): the bone preset (inside
/// above); (3) otherwise the upper threshold of a three-class Otsu over histogram(vol, 256)
/// (inside above). A volume with no finite voxels or a single value: the middle of its range
/// (said so in the rule). Never NaN.
IsoChoice choose_isovalue(const Volume& vol, const VolumeHints& hints);

/// The line the programs print: "isovalue 300 (inside above), chosen by CT in HU (...): ...".
std::string iso_line(const IsoChoice& c);

}  // namespace isotouch::engine
