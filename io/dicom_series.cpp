// The only translation unit that includes ITK's GDCM IO and GDCM headers.
#include "isotouch/io/dicom_series.h"

#include <gdcmScanner.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>
#include <itkGDCMImageIO.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkImage.h>
#include <itkImageSeriesReader.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "isotouch/io/itk_reason.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::io {
using engine::Volume;
using engine::VolumeError;
namespace {

namespace fs = std::filesystem;
using V3 = std::array<double, 3>;

[[noreturn]] void fail(const std::string& folder, const std::string& what) { throw VolumeError(folder + ": " + what); }

std::string name_of(const std::string& file) { return fs::path(file).filename().string(); }

std::string num(double x) {
  std::ostringstream s;
  s << std::setprecision(6) << x;
  return s.str();
}

double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// A few names, "a, b, c and 4 more".
std::string some_names(const std::vector<std::string>& files, std::size_t shown = 5) {
  std::string s;
  for (std::size_t i = 0; i < files.size() && i < shown; ++i) s += (i ? ", " : "") + name_of(files[i]);
  if (files.size() > shown) s += " and " + std::to_string(files.size() - shown) + " more";
  return s;
}

// The tags read from every slice's header (gdcm::Scanner stops before the pixel data).
const gdcm::Tag kModality(0x0008, 0x0060), kSeriesDescription(0x0008, 0x103e), kSliceThickness(0x0018, 0x0050),
    kSpacingBetweenSlices(0x0018, 0x0088), kSeriesUid(0x0020, 0x000e), kPosition(0x0020, 0x0032),
    kOrientation(0x0020, 0x0037), kSamplesPerPixel(0x0028, 0x0002), kFrames(0x0028, 0x0008), kRows(0x0028, 0x0010),
    kColumns(0x0028, 0x0011), kPixelSpacing(0x0028, 0x0030), kBitsAllocated(0x0028, 0x0100);

std::string trimmed(const char* s) {
  std::string t = s ? s : "";
  while (!t.empty() && (t.back() == ' ' || t.back() == '\0')) t.pop_back();
  while (!t.empty() && t.front() == ' ') t.erase(t.begin());
  return t;
}

// A DICOM decimal string ("a\b\c"): its numbers, or fewer than `want` when one is missing
// or not a finite number.
std::vector<double> numbers(const char* s, std::size_t want) {
  std::vector<double> out;
  std::string t = trimmed(s);
  std::size_t at = 0;
  while (at <= t.size() && !t.empty()) {
    const auto bs = t.find('\\', at);
    const std::string tok = trimmed(t.substr(at, bs == std::string::npos ? std::string::npos : bs - at).c_str());
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (tok.empty() || *end != '\0' || !std::isfinite(x)) break;
    out.push_back(x);
    if (bs == std::string::npos) break;
    at = bs + 1;
  }
  if (out.size() > want) out.resize(want);
  return out;
}

// ITK's and GDCM's warnings and errors go to stderr as they happen (a folder without a
// series, positions that are not unique); this reader says what is wrong in its exception
// instead. Both switches are global: restored on the way out.
struct QuietItkGdcm {
  const bool itk_warnings = itk::Object::GetGlobalWarningDisplay();
  const bool gdcm_warnings = gdcm::Trace::GetWarningFlag(), gdcm_errors = gdcm::Trace::GetErrorFlag();
  QuietItkGdcm() {
    itk::Object::GlobalWarningDisplayOff();
    gdcm::Trace::WarningOff();
    gdcm::Trace::ErrorOff();
  }
  ~QuietItkGdcm() {
    itk::Object::SetGlobalWarningDisplay(itk_warnings);
    gdcm::Trace::SetWarning(gdcm_warnings);
    gdcm::Trace::SetError(gdcm_errors);
  }
  QuietItkGdcm(const QuietItkGdcm&) = delete;
  QuietItkGdcm& operator=(const QuietItkGdcm&) = delete;
};

// Uncompressed pixel data must be whole: GDCM reads a file cut short without complaint
// (the missing pixels come back as whatever the buffer held). Find the Pixel Data element
// (7FE0,0010) whose length is the `expected` bytes (implicit VR: tag, 4-byte length;
// explicit VR: tag, OB/OW, 2 reserved bytes, 4-byte length) in the file's first 1 MiB and
// compare the file's size with its end. Encapsulated (compressed) data: not checked here.
void check_pixel_data_whole(const std::string& folder, const std::string& where, const std::string& file,
                            std::uint64_t expected) {
  std::error_code ec;
  const std::uint64_t size = fs::file_size(file, ec);
  if (ec) fail(folder, where + ": cannot read the size of " + name_of(file) + " (" + ec.message() + ")");
  std::ifstream in(file, std::ios::binary);
  std::string head(std::size_t(std::min<std::uint64_t>(size, 1 << 20)), '\0');
  in.read(head.data(), std::streamsize(head.size()));
  head.resize(std::size_t(in.gcount()));
  const std::string tag("\xe0\x7f\x10\x00", 4);
  for (std::size_t at = head.find(tag); at != std::string::npos; at = head.find(tag, at + 1)) {
    for (const std::size_t len_at : {at + 4, at + 8}) {
      if (len_at == at + 8 && !(head.compare(at + 4, 2, "OW") == 0 || head.compare(at + 4, 2, "OB") == 0)) continue;
      if (len_at + 4 > head.size()) continue;
      std::uint32_t len = 0;
      std::memcpy(&len, head.data() + len_at, 4);
      if (len != expected && len != expected + 1) continue;
      const std::uint64_t end = len_at + 4 + std::uint64_t(len);
      if (size < end)
        fail(folder, where + ": " + name_of(file) + " is truncated: its Pixel Data (7FE0,0010) is " + std::to_string(len) +
                         " bytes, the file holds " + std::to_string(size > len_at + 4 ? size - len_at - 4 : 0) +
                         " of them");
      return;
    }
  }
}

struct Slice {
  std::string file;
  V3 position{};  // ImagePositionPatient [mm]
  double along = 0;  // position . normal [mm]
};


// The regular files of `folder`, sorted by name.
std::vector<std::string> folder_files(const std::string& folder) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) fail(folder, "no such folder");
  if (!fs::is_directory(folder, ec)) fail(folder, "not a folder (a DICOM series is read from the folder of its slices)");
  std::vector<std::string> all;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_regular_file(ec)) all.push_back(e.path().string());
  if (ec) fail(folder, "cannot list the folder (" + ec.message() + ")");
  std::sort(all.begin(), all.end());
  if (all.empty()) fail(folder, "no DICOM files: the folder holds no files");
  return all;
}

// The folder's series, by SeriesInstanceUID alone, so that slices of one series that
// differ in size or orientation are refused later rather than split silently. `uids`
// keeps ITK's order.
std::map<std::string, std::vector<std::string>> find_series(const std::string& folder, std::vector<std::string>& uids) {
  std::map<std::string, std::vector<std::string>> series;
  try {
    auto names = itk::GDCMSeriesFileNames::New();
    names->SetUseSeriesDetails(false);
    names->SetRecursive(false);
    names->SetInputDirectory(folder);
    for (const std::string& uid : names->GetSeriesUIDs()) {
      std::vector<std::string> files = names->GetFileNames(uid);
      if (files.empty()) continue;
      uids.push_back(uid);
      series[uid] = std::move(files);
    }
  } catch (const itk::ExceptionObject& e) {
    fail(folder, "cannot scan the folder for DICOM series (" + itk_reason(e.what()) + ")");
  }
  return series;
}

// The files of `all` that belong to no series.
std::vector<std::string> files_outside(const std::vector<std::string>& all,
                                       const std::map<std::string, std::vector<std::string>>& series) {
  std::set<std::string> in_series;
  for (const auto& [uid, files] : series)
    for (const auto& f : files) in_series.insert(fs::path(f).lexically_normal().string());
  std::vector<std::string> others;
  for (const auto& f : all)
    if (!in_series.count(fs::path(f).lexically_normal().string())) others.push_back(f);
  return others;
}

// The series to read (`series_uid`, else the one with the most slices) and its files;
// info gets the series count, the choice and the ignored files.
std::vector<std::string> choose_series(const std::string& folder, const std::string& series_uid, DicomSeriesInfo& info) {
  const std::vector<std::string> all = folder_files(folder);
  std::vector<std::string> uids;
  std::map<std::string, std::vector<std::string>> series = find_series(folder, uids);
  const std::vector<std::string> others = files_outside(all, series);
  if (series.empty())
    fail(folder, all.size() == 1 ? "no DICOM files: its one file (" + some_names(all) + ") is not a DICOM image slice"
                                 : "no DICOM files: none of its " + std::to_string(all.size()) + " files (" +
                                       some_names(all) + ") is a DICOM image slice");
  info.series_in_folder = series.size();
  auto listed = [&](const std::string& except) {
    std::string s;
    for (const auto& u : uids)
      if (u != except) s += (s.empty() ? "" : ", ") + u + " (" + std::to_string(series[u].size()) + " files)";
    return s;
  };
  std::string uid = series_uid;
  if (!uid.empty()) {
    if (!series.count(uid))
      fail(folder, "no DICOM series with SeriesInstanceUID " + uid + " here; the folder holds " + listed(""));
  } else {
    uid = uids.front();
    for (const auto& u : uids)
      if (series[u].size() > series[uid].size()) uid = u;
    if (series.size() > 1)
      info.notes.push_back("the folder holds " + std::to_string(series.size()) + " DICOM series; read " + uid + " (" +
                           std::to_string(series[uid].size()) + " files, the most), not " + listed(uid));
  }
  if (!others.empty())
    info.notes.push_back("ignored " + std::to_string(others.size()) +
                         (others.size() > 1 ? " files that are not DICOM image slices: "
                                            : " file that is not a DICOM image slice: ") +
                         some_names(others));
  info.series_uid = uid;
  return series[uid];
}

// Every slice's header (gdcm::Scanner stops before the pixel data).
class Headers {
 public:
  Headers(const std::string& folder, const std::string& where, const std::vector<std::string>& files) {
    for (const gdcm::Tag& t : {kModality, kSeriesDescription, kSliceThickness, kSpacingBetweenSlices, kSeriesUid,
                               kPosition, kOrientation, kSamplesPerPixel, kFrames, kRows, kColumns, kPixelSpacing,
                               kBitsAllocated})
      scan_.AddTag(t);
    if (!scan_.Scan(files)) fail(folder, where + ": cannot read the slices' headers");
    for (const auto& f : files)
      if (!scan_.IsKey(f.c_str())) fail(folder, where + ": cannot read the header of " + name_of(f));
  }
  const char* raw(const std::string& f, const gdcm::Tag& t) const {
    return scan_.IsKey(f.c_str()) ? scan_.GetValue(f.c_str(), t) : nullptr;
  }
  std::string text(const std::string& f, const gdcm::Tag& t) const { return trimmed(raw(f, t)); }
  std::vector<double> values(const std::string& f, const gdcm::Tag& t, std::size_t want) const {
    return numbers(raw(f, t), want);
  }

 private:
  gdcm::Scanner scan_;
};

// What every slice shares: size, orientation, pixel spacing.
struct SliceFrame {
  std::string rows, cols;        // Rows, Columns as written
  std::vector<double> spacing;   // PixelSpacing: row spacing, column spacing [mm]
  V3 row{}, col{}, normal{};     // direction cosines; normal = row x col, unit
};

// One slice's file against the first's: greyscale, single-frame, same size, orientation
// and pixel spacing.
void check_slice_like_first(const std::string& folder, const std::string& where, const Headers& h,
                            const std::string& f0, const SliceFrame& first, const std::string& f) {
  const std::string spp = h.text(f, kSamplesPerPixel);
  if (!spp.empty() && spp != "1")
    fail(folder, where + ": " + name_of(f) + " has SamplesPerPixel (0028,0002) " + spp +
                     " (a colour image); a volume needs greyscale slices");
  const std::string frames = h.text(f, kFrames);
  if (!frames.empty() && std::atoi(frames.c_str()) > 1)
    fail(folder, where + ": " + name_of(f) + " is a multi-frame image (NumberOfFrames (0028,0008) " + frames +
                     "); only series of single-frame slices are read");
  const std::string r = h.text(f, kRows), c = h.text(f, kColumns);
  if (r.empty() || c.empty()) fail(folder, where + ": " + name_of(f) + " has no Rows (0028,0010) or Columns (0028,0011)");
  if (r != first.rows || c != first.cols)
    fail(folder, where + ": the slices differ in size: " + name_of(f0) + " is " + first.cols + " x " + first.rows + ", " +
                     name_of(f) + " is " + c + " x " + r + " (Columns x Rows)");
  const std::vector<double> iop0 = h.values(f0, kOrientation, 6), iop = h.values(f, kOrientation, 6);
  if (iop.size() != 6)
    fail(folder, where + ": " + name_of(f) + " has no valid ImageOrientationPatient (0020,0037): '" +
                     h.text(f, kOrientation) + "'");
  for (int i = 0; i < 6; ++i)
    if (std::abs(iop[std::size_t(i)] - iop0[std::size_t(i)]) > 1e-4)
      fail(folder, where + ": the slices differ in orientation: ImageOrientationPatient (0020,0037) of " + name_of(f0) +
                       " is " + h.text(f0, kOrientation) + ", of " + name_of(f) + " " + h.text(f, kOrientation));
  const std::vector<double> ps = h.values(f, kPixelSpacing, 2);
  if (ps.size() != 2 || !(ps[0] > 0 && ps[1] > 0))
    fail(folder, where + ": " + name_of(f) + " has no valid PixelSpacing (0028,0030): '" + h.text(f, kPixelSpacing) +
                     "' (must be two positive numbers of mm)");
  const std::vector<double>& ps0 = first.spacing;
  if (std::abs(ps[0] - ps0[0]) > 1e-4 * ps0[0] || std::abs(ps[1] - ps0[1]) > 1e-4 * ps0[1])
    fail(folder, where + ": the slices differ in PixelSpacing (0028,0030): " + name_of(f0) + " has " +
                     h.text(f0, kPixelSpacing) + ", " + name_of(f) + " " + h.text(f, kPixelSpacing));
}

// The frame every slice shares, checked on each; the direction cosines unit and
// perpendicular (voxel size goes in PixelSpacing).
SliceFrame slice_frame(const std::string& folder, const std::string& where, const Headers& h,
                       const std::vector<std::string>& files) {
  const std::string& f0 = files.front();
  SliceFrame fr;
  fr.rows = h.text(f0, kRows);
  fr.cols = h.text(f0, kColumns);
  fr.spacing = h.values(f0, kPixelSpacing, 2);
  for (const auto& f : files) check_slice_like_first(folder, where, h, f0, fr, f);
  const std::vector<double> iop0 = h.values(f0, kOrientation, 6);
  fr.row = {iop0[0], iop0[1], iop0[2]};
  fr.col = {iop0[3], iop0[4], iop0[5]};
  const V3 &row = fr.row, &col = fr.col;
  if (std::abs(dot(row, row) - 1) > 1e-3 || std::abs(dot(col, col) - 1) > 1e-3 || std::abs(dot(row, col)) > 1e-3)
    fail(folder, where + ": ImageOrientationPatient (0020,0037) of " + name_of(f0) + " is " + h.text(f0, kOrientation) +
                     ": the two direction cosines must be unit vectors at right angles (within 0.001)");
  fr.normal = cross(row, col);
  const double len = std::sqrt(dot(fr.normal, fr.normal));
  for (double& x : fr.normal) x /= len;
  return fr;
}

// Slices sorted by position along the normal.
std::vector<Slice> sorted_slices(const std::string& folder, const std::string& where, const Headers& h,
                                 const std::vector<std::string>& files, const V3& normal) {
  std::vector<Slice> slices;
  for (const auto& f : files) {
    const std::vector<double> p = h.values(f, kPosition, 3);
    if (p.size() != 3)
      fail(folder, where + ": " + name_of(f) + " has no valid ImagePositionPatient (0020,0032): '" +
                       h.text(f, kPosition) + "'");
    Slice s;
    s.file = f;
    s.position = {p[0], p[1], p[2]};
    s.along = dot(s.position, normal);
    slices.push_back(s);
  }
  std::stable_sort(slices.begin(), slices.end(), [](const Slice& a, const Slice& b) { return a.along < b.along; });
  return slices;
}

std::string slice_at(const Slice& s) { return name_of(s.file) + " (at " + num(s.along) + " mm)"; }

// The spacing along the normal of two or more sorted slices: the median gap; no repeated
// positions, no missing slices, no uneven gaps. `tol` gets the gap tolerance [mm].
double slice_spacing(const std::string& folder, const std::string& where, const std::vector<Slice>& slices, double& tol) {
  const std::size_t n = slices.size();
  std::vector<double> gaps;
  for (std::size_t i = 1; i < n; ++i) gaps.push_back(slices[i].along - slices[i - 1].along);
  std::vector<double> sorted = gaps;
  std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2), sorted.end());
  const double dz = sorted[sorted.size() / 2];
  tol = std::max(kDicomGapTolMm, kDicomGapTolRel * dz);
  for (std::size_t i = 1; i < n; ++i)
    if (gaps[i - 1] <= tol)
      fail(folder, where + ": two slices at one position: " + slice_at(slices[i - 1]) + " and " + slice_at(slices[i]) +
                       " (ImagePositionPatient (0020,0032) along the slice normal); repeated positions are several "
                       "acquisitions, echoes or time points, not one volume");
  if (!(dz > 0)) fail(folder, where + ": the slices' positions do not advance along their normal");
  for (std::size_t i = 1; i < n; ++i) {
    const double g = gaps[i - 1];
    if (std::abs(g - dz) <= tol) continue;
    std::ostringstream s;
    s << where << ": ";
    const long missing = std::lround(g / dz) - 1;
    if (g >= 1.5 * dz)
      s << (missing == 1 ? "a slice is" : std::to_string(missing) + " slices are") << " missing between "
        << slice_at(slices[i - 1]) << " and " << slice_at(slices[i]) << ": they are " << num(g)
        << " mm apart, the series' slices " << num(dz) << " mm";
    else
      s << "uneven slice spacing: " << slice_at(slices[i - 1]) << " and " << slice_at(slices[i]) << " are " << num(g)
        << " mm apart, the series' slices " << num(dz) << " mm (tolerance " << num(tol) << " mm)";
    s << " (ImagePositionPatient (0020,0032) along the slice normal)";
    fail(folder, s.str());
  }
  return dz;
}

// The stack must run along the normal: a sideways drift is a gantry tilt or a shear,
// which a regular grid cannot hold.
void check_no_shear(const std::string& folder, const std::string& where, const std::vector<Slice>& slices,
                    const V3& normal, double tol) {
  for (std::size_t i = 1; i < slices.size(); ++i) {
    V3 d;
    for (int a = 0; a < 3; ++a) d[std::size_t(a)] = slices[i].position[std::size_t(a)] - slices[0].position[std::size_t(a)];
    const double t = dot(d, normal);
    double side = 0;
    for (int a = 0; a < 3; ++a) side += std::pow(d[std::size_t(a)] - t * normal[std::size_t(a)], 2);
    side = std::sqrt(side);
    if (side > tol)
      fail(folder, where + ": the slices do not stack along their normal: " + name_of(slices[i].file) + " lies " +
                       num(side) + " mm sideways of " + name_of(slices[0].file) +
                       " (gantry tilt or shear; ImagePositionPatient (0020,0032))");
  }
}

// The spacing along the normal [mm]: from the gaps of two or more slices; a single
// slice's SpacingBetweenSlices, else SliceThickness, else 1 mm (a note says which).
double stack_spacing(const std::string& folder, const std::string& where, const Headers& h,
                     const std::vector<Slice>& slices, const V3& normal, const std::string& f0, DicomSeriesInfo& info) {
  if (slices.size() > 1) {
    double tol = 0;
    const double dz = slice_spacing(folder, where, slices, tol);
    check_no_shear(folder, where, slices, normal, tol);
    return dz;
  }
  double dz = 1.0;
  const std::vector<double> sb = h.values(f0, kSpacingBetweenSlices, 1), st = h.values(f0, kSliceThickness, 1);
  if (!sb.empty() && sb[0] > 0) dz = sb[0];
  else if (!st.empty() && st[0] > 0) dz = st[0];
  info.notes.push_back("a single slice: its thickness along the normal is taken as " + num(dz) + " mm");
  return dz;
}

// Dimensions, extent, voxel count, origin and memory within the limits of every volume
// (io::check_volume_limits); the memory: ITK's float image and the float copy.
void check_limits(const std::string& folder, const std::string& where, const std::array<std::uint64_t, 3>& dims,
                  const double (&sp_mm)[3], const Slice& first) {
  const VolumeFields fields{"Columns (0028,0011), Rows (0028,0010) and the slice count",
                            "PixelSpacing (0028,0030) and the slice gap",
                            "ImagePositionPatient (0020,0032) of " + name_of(first.file), "ImageOrientationPatient"};
  try {
    check_volume_limits(folder, dims, {sp_mm[0], sp_mm[1], sp_mm[2]},
                        {first.position[0], first.position[1], first.position[2]}, sizeof(float), "float", fields);
  } catch (const VolumeError& e) {
    fail(folder, where + ": " + std::string(e.what()).substr(folder.size() + 2));
  }
}

using Image = itk::Image<float, 3>;

// The pixels of `files` in their order, rescaled by GDCM (RescaleSlope, RescaleIntercept);
// `component` gets the stored pixel type.
Image::Pointer read_pixels(const std::string& folder, const std::string& where, const std::vector<std::string>& files,
                           std::string& component) {
  auto io = itk::GDCMImageIO::New();
  auto reader = itk::ImageSeriesReader<Image>::New();
  reader->SetImageIO(io);
  reader->SetFileNames(files);
  reader->MetaDataDictionaryArrayUpdateOff();
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    // Which file: read each alone (the series reader's message does not always say).
    for (const auto& f : files) {
      try {
        auto one = itk::GDCMImageIO::New();
        one->SetFileName(f);
        one->ReadImageInformation();
        std::vector<char> buf(one->GetImageSizeInBytes());
        one->Read(buf.data());
      } catch (const itk::ExceptionObject& e1) {
        fail(folder, where + ": cannot read " + name_of(f) + " (" + itk_reason(e1.what()) + ")");
      }
    }
    fail(folder, where + ": ITK could not read the series (" + itk_reason(e.what()) + ")");
  }
  component = itk::ImageIOBase::GetComponentTypeAsString(io->GetComponentType());
  return reader->GetOutput();
}

// The volume: grid from the first slice's position, the spacing and the frame's cosines.
Volume make_volume(const std::string& folder, const Image& img, const std::array<std::uint64_t, 3>& dims,
                   const double (&sp_mm)[3], const SliceFrame& fr, const Slice& first) {
  Volume v;
  v.grid.dims = {int(dims[0]), int(dims[1]), int(dims[2])};
  v.grid.spacing_m = {sp_mm[0] * 1e-3, sp_mm[1] * 1e-3, sp_mm[2] * 1e-3};
  v.grid.origin_m = {first.position[0] * 1e-3, first.position[1] * 1e-3, first.position[2] * 1e-3};
  for (int r = 0; r < 3; ++r) {
    v.direction[std::size_t(r * 3 + 0)] = fr.row[std::size_t(r)];
    v.direction[std::size_t(r * 3 + 1)] = fr.col[std::size_t(r)];
    v.direction[std::size_t(r * 3 + 2)] = fr.normal[std::size_t(r)];
  }
  const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  v.direction_is_identity = true;
  for (int i = 0; i < 9; ++i)
    if (std::abs(v.direction[std::size_t(i)] - id[i]) > 1e-6) v.direction_is_identity = false;
  const float* buf = img.GetBufferPointer();
  v.voxels.assign(buf, buf + v.grid.voxel_count());
  v.path = folder;
  v.reader = "itk:GDCMImageIO";
  return v;
}

}  // namespace

Volume load_dicom_series(const std::string& folder, const std::string& series_uid, DicomSeriesInfo* info_out) {
  const QuietItkGdcm quiet;
  DicomSeriesInfo info;
  const std::vector<std::string> files = choose_series(folder, series_uid, info);
  const std::string where = "DICOM series " + info.series_uid;
  const Headers h(folder, where, files);
  const std::string& f0 = files.front();
  {
    const std::string mod = h.text(f0, kModality), desc = h.text(f0, kSeriesDescription);
    info.description = mod + (mod.empty() || desc.empty() ? "" : " ") + desc;
    info.modality = mod;
  }
  const SliceFrame fr = slice_frame(folder, where, h, files);
  const std::vector<Slice> slices = sorted_slices(folder, where, h, files, fr.normal);
  const double dz = stack_spacing(folder, where, h, slices, fr.normal, f0, info);

  const std::array<std::uint64_t, 3> dims{std::uint64_t(std::strtoull(fr.cols.c_str(), nullptr, 10)),
                                          std::uint64_t(std::strtoull(fr.rows.c_str(), nullptr, 10)),
                                          std::uint64_t(slices.size())};
  const double sp_mm[3] = {fr.spacing[1], fr.spacing[0], dz};
  check_limits(folder, where, dims, sp_mm, slices.front());
  for (const auto& f : files) {
    const int bits = std::atoi(h.text(f, kBitsAllocated).c_str());
    if (bits > 0) check_pixel_data_whole(folder, where, f, dims[0] * dims[1] * std::uint64_t(bits) / 8);
  }

  std::vector<std::string> sorted_files;
  for (const auto& s : slices) sorted_files.push_back(s.file);
  std::string component;
  Image::Pointer img = read_pixels(folder, where, sorted_files, component);
  const auto size = img->GetLargestPossibleRegion().GetSize();
  if (size[0] != dims[0] || size[1] != dims[1] || size[2] != dims[2])
    fail(folder, where + ": ITK read " + std::to_string(size[0]) + " x " + std::to_string(size[1]) + " x " +
                     std::to_string(size[2]) + " voxels, the headers say " + std::to_string(dims[0]) + " x " +
                     std::to_string(dims[1]) + " x " + std::to_string(dims[2]));
  Volume v = make_volume(folder, *img, dims, sp_mm, fr, slices.front());
  v.component_type = component;
  v.update_stats();
  info.files = std::move(sorted_files);
  if (info_out) *info_out = std::move(info);
  return v;
}

}  // namespace isotouch::io
