// volume_io.h - read MetaImage (.mhd/.mha), NRRD (.nrrd/.nhdr) and NIfTI (.nii/.nii.gz).
#pragma once
#include <cstdint>
#include <string>

#include "volume.h"

namespace isotouch::engine {

/// Largest volume accepted [voxels]; beyond it the header is called absurd.
inline constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 31;

/// Load a volume with ITK's image IO (MetaImageIO, NrrdImageIO, NiftiImageIO). Spacing
/// and origin are converted from the file's millimetres to metres. Accepted voxel types:
/// 8/16/32/64-bit signed and unsigned integers, float and double (converted to float).
/// NRRD headers that ITK rejects but teem accepts (e.g. `spacings` together with
/// `space`, as in VTK's headsq quarter.nhdr) are read with teem's nrrdLoad.
/// @throws VolumeError naming the file and the problem: missing file, unknown format,
///         unknown voxel type, more than one component, absurd dimensions, truncated data.
Volume load_volume(const std::string& path);

}  // namespace isotouch::engine
