// volume_io.h - read MetaImage (.mhd/.mha), NRRD (.nrrd/.nhdr), NIfTI (.nii/.nii.gz) and
// DICOM series folders.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "isotouch/engine/volume.h"

namespace isotouch::io {

/// Largest volume accepted [voxels]; beyond it the header is called absurd.
inline constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 31;
/// Largest extent (dims - 1) * spacing accepted along any axis [m]: no scanned or
/// sculpted volume a hand can feel is larger, and beyond it marches never end.
inline constexpr double kMaxExtentM = 10.0;
/// Largest |origin| component accepted [m].
inline constexpr double kMaxOriginM = 1000.0;

/// The header fields a volume's numbers came from, named in messages.
struct VolumeFields {
  std::string dims, spacing, origin, direction;
};

/// The limits every volume meets before its voxels are allocated, whatever its format
/// (MetaImage, NRRD, NIfTI, DICOM, .vdb): dims in [1, 2^20] per axis and at most kMaxVoxels
/// in all; spacing finite and positive with an extent (dims - 1) x spacing of at most
/// kMaxExtentM per axis; origin finite and within kMaxOriginM; the memory the load needs
/// (the voxels as stored, `stored_bytes_per_voxel` each, plus the float copy) at most 3/4
/// of what this process may use (io::memory_budget_bytes).
/// @param dims voxels per axis as the file gives them; spacing_mm, origin_mm [mm] (the
///        grid-world frame); type the voxel type's name, for messages.
/// @throws engine::VolumeError "PATH: field 'F' along axis A is V ..." naming the field.
void check_volume_limits(const std::string& path, const std::array<std::uint64_t, 3>& dims,
                         const std::array<double, 3>& spacing_mm, const std::array<double, 3>& origin_mm,
                         std::uint64_t stored_bytes_per_voxel, const std::string& type, const VolumeFields& fields);

/// The direction matrix D (row-major, columns are the index axes) must be finite and
/// orthonormal (|D^T D - I| <= 1e-3 per entry). @throws engine::VolumeError naming `field`
/// and D.
void check_direction(const std::string& path, const std::array<double, 9>& direction, const std::string& field);

/// The memory this process may allocate [bytes]: the smallest of the machine's physical
/// memory, the address-space limit (RLIMIT_AS) and the cgroup's memory.max; 0 if unknown.
std::uint64_t memory_budget_bytes();

/// Refuses, before anything opens it, a path that is not a regular file: a FIFO (whose
/// open() blocks until a writer comes), a socket, a device or a folder. Symlinks are followed.
/// @param why what the file must be, the end of the message.
/// @throws engine::VolumeError "PATH: not a regular file (a FIFO): WHY" (or the OS error).
void require_regular_file(const std::string& path, const std::string& why);

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

/// The free text a NIfTI or NRRD header says about its data, as (field, value) pairs: NIfTI's
/// `descrip`, `intent_name` and `aux_file`; NRRD's `content` and every key/value pair. Empty
/// for other formats, or when the header cannot be read (load_volume names why). Reads the
/// header only.
std::vector<std::pair<std::string, std::string>> header_text_fields(const std::string& path);

}  // namespace isotouch::io
