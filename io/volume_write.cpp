// volume_write.cpp - ITK's image writers (ImageIOBase, as volume_io.cpp reads), in a
// translation unit of their own.
#include "isotouch/io/volume_write.h"

#include <itkImageIOBase.h>
#include <itkImageIORegion.h>
#include <itkMetaImageIO.h>
#include <itkNiftiImageIO.h>
#include <itkNrrdImageIO.h>

#include <algorithm>
#include <cctype>
#include <string>
#include <vector>

#include "isotouch/io/output_file.h"

namespace isotouch::io {
using engine::Volume;
using engine::VolumeError;
namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

itk::ImageIOBase::Pointer writer_for(const std::string& path) {
  const std::string p = lower(path);
  if (ends_with(p, ".mha")) return itk::MetaImageIO::New().GetPointer();
  if (ends_with(p, ".nrrd")) return itk::NrrdImageIO::New().GetPointer();
  if (ends_with(p, ".nii") || ends_with(p, ".nii.gz")) return itk::NiftiImageIO::New().GetPointer();
  return nullptr;
}

}  // namespace

bool itk_writable(const std::string& path) { return writer_for(path) != nullptr; }

void save_volume_itk(const Volume& v, const std::string& path) {
  if (ends_with(lower(path), ".mhd"))
    throw VolumeError(path + ": .mhd writes a second .raw file that cannot be replaced atomically: use .mha (one file)");
  if (!writer_for(path))
    throw VolumeError(path + ": unknown volume format: write .mha (MetaImage), .nrrd (NRRD), .nii or .nii.gz (NIfTI), or .vdb");
  const auto& g = v.grid;
  try {
    io::write_output(path, [&](const std::string& file) {
      itk::ImageIOBase::Pointer w = writer_for(path);  // the temp file ends in the same extension
      w->SetNumberOfDimensions(3);
      const double spacing_mm[3] = {g.spacing_m.x * 1e3, g.spacing_m.y * 1e3, g.spacing_m.z * 1e3};
      const double origin_mm[3] = {g.origin_m.x * 1e3, g.origin_m.y * 1e3, g.origin_m.z * 1e3};
      for (unsigned a = 0; a < 3; ++a) {
        w->SetDimensions(a, itk::SizeValueType(g.dims[a]));
        w->SetSpacing(a, spacing_mm[a]);
        w->SetOrigin(a, origin_mm[a]);
        std::vector<double> column(3);  // ITK's direction a: the physical direction of index axis a
        for (unsigned r = 0; r < 3; ++r) column[r] = v.direction[std::size_t(3 * r + a)];
        w->SetDirection(a, column);
      }
      w->SetPixelType(itk::IOPixelEnum::SCALAR);
      w->SetComponentType(itk::IOComponentEnum::FLOAT);
      w->SetNumberOfComponents(1);
      w->SetUseCompression(ends_with(lower(path), ".gz"));
      itk::ImageIORegion region(3);
      for (unsigned a = 0; a < 3; ++a) {
        region.SetIndex(a, 0);
        region.SetSize(a, itk::SizeValueType(g.dims[a]));
      }
      w->SetIORegion(region);
      w->SetFileName(file);
      w->WriteImageInformation();
      w->Write(v.voxels.data());
    }, /*keep_extension=*/true);
  } catch (const itk::ExceptionObject& e) {
    throw VolumeError(path + ": ITK could not write it: " + e.GetDescription());
  } catch (const io::OutputError& e) {
    throw VolumeError(e.what());
  }
}

}  // namespace isotouch::io
