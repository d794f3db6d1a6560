// volume_io.h - read MetaImage (.mhd/.mha), NRRD (.nrrd/.nhdr), NIfTI (.nii/.nii.gz) and
// DICOM series folders.
#pragma once
#include <cstdint>
#include <string>

#include "volume.h"

namespace isotouch::io {

/// Largest volume accepted [voxels]; beyond it the header is called absurd.
inline constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 31;
/// Largest extent (dims - 1) * spacing accepted along any axis [m]: no scanned or
/// sculpted volume a hand can feel is larger, and beyond it marches never end.
inline constexpr double kMaxExtentM = 10.0;
/// Largest |origin| component accepted [m].
inline constexpr double kMaxOriginM = 1000.0;

/// Load a volume with ITK's image IO (MetaImageIO, NrrdImageIO, NiftiImageIO). Spacing
/// and origin are converted from the file's millimetres to metres. Accepted voxel types:
/// 8/16/32/64-bit signed and unsigned integers, float and double (converted to float).
/// NRRD headers that ITK rejects but teem accepts (e.g. `spacings` together with
/// `space`, as in VTK's headsq quarter.nhdr) are read with teem's nrrdLoad.
/// The direction matrix is kept in engine::Volume::direction (see engine::Volume for the two frames).
/// A folder is read as a DICOM series with io::load_dicom_series (dicom_series.h: one
/// series, the one with the most slices when there are several; its notes, such as which
/// series was taken, go to stderr as "isotouch: note: FOLDER: ...").
/// @throws VolumeError naming the file, the header field and its value (for a folder, what
///         load_dicom_series throws): missing file,
///         unknown format, unknown voxel type, more than one component, dimensions not in
///         [1, 2^20] (said as the file wrote them, e.g. `DimSize` -64) or above kMaxVoxels
///         in all, spacing not finite and positive, extent above kMaxExtentM, origin not
///         finite or beyond kMaxOriginM, truncated data; for MetaImage also a missing
///         `ElementDataFile` and a raw file whose size is not `HeaderSize` + DimSize x
///         ElementType bytes (too short, or longer as when MET_UCHAR is declared over
///         16-bit data).
engine::Volume load_volume(const std::string& path);

}  // namespace isotouch::io
