// scan.h - a volume as a user brings it (any file isotouch reads, or a DICOM folder) with what
// its header says beyond the voxels: the modality, an isovalue it stores. The isovalue it
// opens at follows from both (engine::choose_isovalue).
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "isotouch/engine/iso_choice.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/vdb_io.h"

namespace isotouch::io {

/// A loaded volume and its header's hints.
struct Scan {
  engine::Volume volume;
  engine::VolumeHints hints;
};

/// Loads `path` as load_any_volume does (.vdb through load_vdb, a folder as a DICOM series,
/// else load_volume) and reads its hints: a .vdb's suggested isosurface (save_vdb's metadata
/// or a level set's zero), a DICOM series' Modality, a MetaImage's `Modality` (MET_MOD_CT ->
/// "CT"), a NIfTI's or NRRD's header text (read_text_hints). @throws what those loaders throw (engine::VolumeError naming the file).
Scan load_scan(const std::string& path);

/// The isovalue a scan opens at (engine::choose_isovalue of its volume and hints).
inline engine::IsoChoice choose_isovalue(const Scan& s) { return engine::choose_isovalue(s.volume, s.hints); }

/// A MetaImage header's (.mhd, .mha) `Modality` without its MET_MOD_ prefix ("CT", "MR");
/// "" when absent or for other formats. Reads the header's text up to ElementDataFile.
std::string metaimage_modality(const std::string& path);

/// A NIfTI's or NRRD's header text (header_text_fields) read into `hints`: a word "CT" or
/// "computed tomography" sets the modality, "HU" or "Hounsfield" the units, each with where it
/// was said ("NIfTI descrip 'CT abdomen'"). `format` names the format in that. A modality or
/// units already known are kept.
void read_text_hints(const std::string& format, const std::vector<std::pair<std::string, std::string>>& fields,
                     engine::VolumeHints& hints);

/// Where a .vdb's suggested isosurface comes from, for messages: "level set" (a level set not
/// written by isotouch: its zero) or ".vdb metadata" (save_vdb's isotouch_isovalue).
std::string suggested_source(const LoadedVdb& l);

/// The file name's extension in lower case (".vdb", ".gz"), "" if none.
std::string lower_extension(const std::string& path);

}  // namespace isotouch::io
