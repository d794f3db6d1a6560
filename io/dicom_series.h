// dicom_series.h - read a folder of DICOM slices (one CT/MR series) as a volume.
//
// A plain C++ API: every ITK and GDCM include stays in dicom_series.cpp (slow to compile).
// io::load_volume calls load_dicom_series when its path is a folder, so a DICOM series
// folder goes wherever a volume file does (run, check, render, export, scenes).
#pragma once
#include <cstddef>
#include <string>
#include <vector>

#include "isotouch/engine/volume.h"

namespace isotouch::io {

/// Largest difference between one gap of adjacent slices (along the slice normal) and the
/// series' spacing (the median gap) accepted: 1 % of the spacing, at least 0.02 mm
/// (positions are often written with two decimals). Beyond it the series is refused as
/// unevenly spaced, or as missing slices when the gap is 1.5 spacings or more.
inline constexpr double kDicomGapTolRel = 0.01;
inline constexpr double kDicomGapTolMm = 0.02;

/// What load_dicom_series found and chose, for messages.
struct DicomSeriesInfo {
  std::string series_uid;            ///< SeriesInstanceUID (0020,000E) of the series read
  std::string description;           ///< Modality and SeriesDescription, e.g. "CT 5mm"
  std::string modality;              ///< Modality (0008,0060) of its first slice, e.g. "CT"; "" if absent
  std::vector<std::string> files;    ///< the slice files, in index z order (along the normal)
  std::size_t series_in_folder = 0;  ///< series found in the folder
  /// What the reader chose or ignored, one sentence each (several series: which one was
  /// taken and why; files that are not DICOM images). Empty for a clean one-series folder.
  std::vector<std::string> notes;
};

/// Load the DICOM series in `folder` (not its subfolders) with ITK's GDCM IO:
/// itk::GDCMSeriesFileNames finds the series (grouped by SeriesInstanceUID only),
/// itk::ImageSeriesReader + itk::GDCMImageIO read the pixels.
///
/// Series: `series_uid` if given; else the folder's only series; else the one with the most
/// slices (a note in info->notes names it and the others). Files that are not DICOM images
/// are ignored (a note names them).
/// Values: RescaleSlope / RescaleIntercept applied (HU for CT), as float.
/// Geometry (the volume's physical frame is DICOM's LPS, in metres): index x runs along the
/// rows (ImageOrientationPatient's first cosine), y down the columns (its second), z along
/// the slice normal (their cross product); slices are sorted by ImagePositionPatient along
/// that normal, origin = the first slice's ImagePositionPatient, spacing = PixelSpacing
/// (column spacing, row spacing) and the median gap between adjacent slices (a single
/// slice: SpacingBetweenSlices, else SliceThickness, else 1 mm).
/// Volume::reader is "itk:GDCMImageIO", path = `folder`.
/// @throws engine::VolumeError "FOLDER: ..." naming the folder, the file and the value:
///         no such folder; no DICOM files (an empty folder, or which files are there);
///         an unknown series_uid (the series present are listed); slices of different
///         size (Rows x Columns), orientation or PixelSpacing; a slice without
///         ImagePositionPatient / ImageOrientationPatient; colour (SamplesPerPixel > 1) or
///         multi-frame files; two slices at one position; slices that do not stack along
///         their normal (gantry tilt, shear); missing slices or uneven spacing (the two
///         files and their positions named); dimensions, extent, origin or memory beyond
///         the limits io::load_volume applies; a file ITK cannot read (named, with its reason).
engine::Volume load_dicom_series(const std::string& folder, const std::string& series_uid = "",
                                 DicomSeriesInfo* info = nullptr);

}  // namespace isotouch::io
