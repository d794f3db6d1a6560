// volume_write.h - a volume saved as MetaImage (.mha), NRRD (.nrrd) or NIfTI (.nii, .nii.gz)
// through ITK's writers, so 3D Slicer and other tools open an edited volume.
#pragma once
#include <string>

#include "isotouch/engine/volume.h"

namespace isotouch::io {

/// True for the names save_volume_itk writes: .mha, .nrrd, .nii, .nii.gz (any case).
bool itk_writable(const std::string& path);

/// Writes `volume` as 32-bit float voxels with its spacing and origin (m -> mm) and its
/// direction D, through ITK's ImageFileWriter (the format from the name), via the one output
/// writer: a regular file is replaced whole or not at all, a device or FIFO is streamed.
/// .mhd is refused (it writes a second .raw file that cannot be replaced atomically: use .mha).
/// @throws VolumeError naming the path (unsupported name, built without ITK, ITK's error).
void save_volume_itk(const engine::Volume& volume, const std::string& path);

}  // namespace isotouch::io
