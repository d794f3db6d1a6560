// With dicom_series.cpp, the only translation units that include ITK and teem headers (slow to compile).
#include "isotouch/io/volume_io.h"
#include "isotouch/io/itk_reason.h"

#include "isotouch/io/dicom_series.h"
#include "isotouch/io/files.h"

#include <itkImageIOBase.h>
#include <itkImageIORegion.h>
#include <itkMetaDataObject.h>
#include <itkMetaImageIO.h>
#include <itkNiftiImageIO.h>
#include <itkNrrdImageIO.h>
#include <metaImage.h>
#include <metaUtils.h>

#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

#ifdef ISOTOUCH_HAVE_TEEM
#include <teem/nrrd.h>
#endif

namespace isotouch::io {
using core::dot;
using engine::Volume;
using engine::VolumeError;
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw VolumeError(path + ": " + what);
}

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool is_nrrd(const std::string& path) {
  const std::string l = lower(path);
  return ends_with(l, ".nrrd") || ends_with(l, ".nhdr");
}

template <class T>
void convert(const char* src, std::size_t n, std::vector<float>& out) {
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    T v;
    std::memcpy(&v, src + i * sizeof(T), sizeof(T));
    out[i] = static_cast<float>(v);
  }
}

// Header field names per format, for messages.
VolumeFields fields_of(const std::string& reader_class) {
  if (reader_class == "MetaImageIO") return {"DimSize", "ElementSpacing", "Offset", "TransformMatrix"};
  if (reader_class == "NiftiImageIO")
    return {"dim", "pixdim", "qoffset/srow", "sform (srow_x/y/z) or qform (quatern_b/c/d)"};
  return {"sizes", "spacings/space directions", "space origin", "space directions"};  // NRRD (ITK or teem)
}

// A size that came from a negative number in the file wraps to a huge unsigned one:
// say it as the file wrote it.
std::string as_written(std::uint64_t d) {
  if (d >= (std::uint64_t(1) << 63)) return std::to_string(std::int64_t(d));
  if (d >= (std::uint64_t(1) << 31) && d < (std::uint64_t(1) << 32))
    return std::to_string(std::int64_t(d) - (std::int64_t(1) << 32));
  return std::to_string(d);
}

void check_dims(const std::string& path, const std::array<std::uint64_t, 3>& d, const std::string& field) {
  std::uint64_t total = 1;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0 || d[a] > (std::uint64_t(1) << 20))
      fail(path, std::string("field '") + field + "' along axis " + std::to_string(a) + " is " +
                     as_written(d[a]) + " (must be a voxel count in [1, 1048576])");
    total *= d[a];
  }
  if (total > kMaxVoxels) {
    std::ostringstream s;
    s << "absurd dimensions (field '" << field << "') " << d[0] << " x " << d[1] << " x " << d[2] << " ("
      << total << " voxels; the limit is " << kMaxVoxels << ")";
    fail(path, s.str());
  }
}

// The memory a load needs (the file's voxels as read, plus the float copy) against what
// this machine has: refused before anything is allocated, naming the dims and the bytes.
void check_memory(const std::string& path, const std::array<std::uint64_t, 3>& d, std::uint64_t bytes_per_voxel,
                  const std::string& type) {
  const std::uint64_t n = d[0] * d[1] * d[2];
  const std::uint64_t need = n * (bytes_per_voxel + sizeof(float));
  const std::uint64_t have = memory_budget_bytes();
  if (have > 0 && need > have / 4 * 3) {
    std::ostringstream s;
    s << d[0] << " x " << d[1] << " x " << d[2] << " voxels of " << type << " need " << (need >> 20)
      << " MiB to load (the voxels as stored plus a float copy), more than 3/4 of the " << (have >> 20)
      << " MiB of memory this process may use";
    fail(path, s.str());
  }
}

// Spacing and origin in mm as the file gives them; the extent bound keeps every march
// over the volume (script, servo) finite and the coordinates meaningful.
void check_spacing_origin(const std::string& path, const std::array<std::uint64_t, 3>& d, const double sp_mm[3],
                          const double org_mm[3], const VolumeFields& f) {
  for (int a = 0; a < 3; ++a) {
    std::ostringstream s;
    s << "field '" << f.spacing << "' along axis " << a << " is " << sp_mm[a] << " mm";
    if (!(std::isfinite(sp_mm[a]) && sp_mm[a] > 0.0)) fail(path, s.str() + " (must be a positive number of mm)");
    const double extent_m = double(d[a] > 1 ? d[a] - 1 : 1) * sp_mm[a] * 1e-3;
    if (extent_m > kMaxExtentM) {
      s << ": the volume's extent along it would be " << extent_m << " m (the limit is " << kMaxExtentM << " m)";
      fail(path, s.str());
    }
    if (!(std::isfinite(org_mm[a]) && std::abs(org_mm[a]) * 1e-3 <= kMaxOriginM)) {
      std::ostringstream o;
      o << "field '" << f.origin << "' along axis " << a << " is " << org_mm[a] << " mm (must be finite, within "
        << kMaxOriginM << " m)";
      fail(path, o.str());
    }
  }
}

void set_spacing_origin(const std::string& path, Volume& v, const std::array<std::uint64_t, 3>& d,
                        const double sp_mm[3], const double org_mm[3], const VolumeFields& f) {
  check_spacing_origin(path, d, sp_mm, org_mm, f);
  v.grid.spacing_m = {sp_mm[0] * 1e-3, sp_mm[1] * 1e-3, sp_mm[2] * 1e-3};
  v.grid.origin_m = {org_mm[0] * 1e-3, org_mm[1] * 1e-3, org_mm[2] * 1e-3};
}

// The bytes a zlib or gzip stream from byte `offset` of `path` inflates to, counted up to
// `limit` (it stops there), through 64 kB buffers.
std::uint64_t inflated_bytes(const std::string& path, std::uint64_t offset, std::uint64_t limit) {
  std::ifstream in(path, std::ios::binary);
  in.seekg(std::streamoff(offset));
  z_stream zs{};
  if (inflateInit2(&zs, 15 + 32) != Z_OK) return 0;  // 15 + 32: zlib or gzip header
  std::vector<unsigned char> src(1 << 16), dst(1 << 16);
  std::uint64_t total = 0;
  for (int rc = Z_OK; rc == Z_OK && total < limit;) {
    if (zs.avail_in == 0) {
      in.read(reinterpret_cast<char*>(src.data()), std::streamsize(src.size()));
      zs.next_in = src.data();
      zs.avail_in = unsigned(in.gcount());
      if (zs.avail_in == 0) break;
    }
    zs.next_out = dst.data();
    zs.avail_out = unsigned(dst.size());
    rc = inflate(&zs, Z_NO_FLUSH);
    total += dst.size() - zs.avail_out;
  }
  inflateEnd(&zs);
  return total;
}

// Compressed voxel data must inflate to the bytes the header promises: checked before the
// voxels are allocated (a few-kB file may promise gigabytes).
void check_inflated(const std::string& path, const std::string& field, const std::string& data_path,
                    std::uint64_t offset, std::uint64_t need) {
  const std::uint64_t have = inflated_bytes(data_path, offset, need);
  if (have < need)
    fail(path, "voxel data truncated: the compressed data of " + field + " inflate to " + std::to_string(have) +
                   " bytes, the header promises " + std::to_string(need));
}

// MetaImage: read the header with MetaIO (ITK's own parser) and check what ITK's reader
// lets through: non-positive DimSize, non-finite ElementSpacing, a missing data file, and
// a raw file whose size is not HeaderSize + DimSize x ElementType (ITK only warns on a
// short read, and reads a prefix of a longer file).
// MetaIO stops at the first number it cannot read (e.g. `ElementSpacing = nan 1 1`) and
// then complains about a later field, or ITK says "No such file or directory". Only after
// MetaIO has refused the header: find a numeric field whose value is not a finite number.
void explain_metaimage_failure(const std::string& path) {
  static const std::set<std::string> numeric = {
      "NDims", "DimSize", "ElementSpacing", "ElementSize", "Offset", "Position", "Origin",
      "TransformMatrix", "Rotation", "Orientation", "CenterOfRotation", "HeaderSize",
      "ElementNumberOfChannels", "ElementMin", "ElementMax"};
  std::ifstream in(path, std::ios::binary);
  std::string line;
  for (int n = 0; n < 200 && std::getline(in, line); ++n) {
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    std::string key = line.substr(0, eq), val = line.substr(eq + 1);
    auto trim = [](std::string& t) {
      while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.pop_back();
      while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.erase(t.begin());
    };
    trim(key);
    trim(val);
    if (key == "ElementDataFile") break;  // the header ends here
    if (!numeric.count(key)) continue;
    std::istringstream toks(val);
    std::string tok;
    while (toks >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
        fail(path, "field '" + key + "' = " + val + ": '" + tok + "' is not a finite number");
    }
  }
}

/// std::cerr swallowed while it lives: MetaIO prints its parse errors there ("MetaImage:
/// M_Read: Error parsing file"), ahead of the one clear line the loader throws.
class QuietCerr {
 public:
  QuietCerr() : old_(std::cerr.rdbuf(sink_.rdbuf())) {}
  ~QuietCerr() { release(); }
  /// std::cerr back, now.
  void release() {
    if (old_) std::cerr.rdbuf(old_);
    old_ = nullptr;
  }
  /// What was written to std::cerr meanwhile.
  std::string text() const { return sink_.str(); }
  QuietCerr(const QuietCerr&) = delete;
  QuietCerr& operator=(const QuietCerr&) = delete;

 private:
  std::ostringstream sink_;
  std::streambuf* old_;
};

void check_metaimage(const std::string& path) {
  MetaImage mi;
  QuietCerr metaio;
  const bool read = mi.Read(path.c_str(), false);
  const std::string said = metaio.text();
  metaio.release();
  if (!read) {
    explain_metaimage_failure(path);
    // MetaIO's first complaint is the cause ("DimSize defined prior to defining NDims"); ITK's
    // own reader would only add a stale errno ("No such file or directory").
    fail(path, "MetaIO cannot read the header: " + said.substr(0, said.find('\n')));
  }
  const int nd = mi.NDims();
  if (nd < 1 || nd > 4) return;
  std::ostringstream dims_s, sp_s;
  for (int a = 0; a < nd; ++a) {
    dims_s << (a ? " " : "") << mi.DimSize(a);
    sp_s << (a ? " " : "") << mi.ElementSpacing(a);
  }
  std::uint64_t count = 1;
  for (int a = 0; a < nd; ++a) {
    if (mi.DimSize(a) <= 0 || mi.DimSize(a) > (1 << 20))
      fail(path, "field 'DimSize' = " + dims_s.str() + ": axis " + std::to_string(a) + " is " +
                     std::to_string(mi.DimSize(a)) + " (must be a voxel count in [1, 1048576])");
    count *= std::uint64_t(mi.DimSize(a));
  }
  for (int a = 0; a < nd; ++a)
    if (!(std::isfinite(mi.ElementSpacing(a)) && mi.ElementSpacing(a) > 0)) {
      std::ostringstream s;
      s << "field 'ElementSpacing' = " << sp_s.str() << ": axis " << a << " is " << mi.ElementSpacing(a)
        << " (must be a positive number of mm)";
      fail(path, s.str());
    }
  if (count > kMaxVoxels) return;  // check_dims names it
  const std::string name = mi.ElementDataFileName();
  if (name.empty()) return;
  // LOCAL (.mha): the data follow the header, from the byte after the ElementDataFile line.
  const bool local = name == "LOCAL" || name == "Local" || name == "local";
  if (name.rfind("LIST", 0) == 0 || name.find('%') != std::string::npos) return;  // one file per slice
  fs::path data(name);
  if (local) data = path;
  else if (data.is_relative()) data = fs::path(path).parent_path() / data;
  std::error_code ec;
  if (!fs::exists(data, ec))
    fail(path, "field 'ElementDataFile' = '" + name + "': no such file (looked for " + data.string() + ")");
  require_regular_file(data.string(), "the voxel data of " + path + " (field 'ElementDataFile') must be a regular file");
  std::uint64_t data_start = 0;
  if (local) {
    std::ifstream in(path, std::ios::binary);
    std::string head(1 << 16, '\0');
    in.read(head.data(), std::streamsize(head.size()));
    head.resize(std::size_t(in.gcount()));
    const auto key = head.find("ElementDataFile");
    const auto eol = key == std::string::npos ? key : head.find('\n', key);
    if (eol == std::string::npos) return;  // ITK will complain
    data_start = eol + 1;
  }
  int type_bytes = 0;
  MET_SizeOfType(mi.ElementType(), &type_bytes);
  char type_name[64] = {};
  MET_TypeToString(mi.ElementType(), type_name);
  const int channels = std::max(1, mi.ElementNumberOfChannels());
  if (type_bytes <= 0) return;  // unknown type: ITK names it
  const std::uint64_t need = count * std::uint64_t(type_bytes) * std::uint64_t(channels);
  if (mi.CompressedData()) {
    check_inflated(path, "field 'ElementDataFile' = '" + name + "'", data.string(), data_start, need);
    return;
  }
  const std::uint64_t file_bytes = fs::file_size(data, ec);
  if (ec) fail(path, "field 'ElementDataFile' = '" + name + "': cannot read its size (" + ec.message() + ")");
  const std::uint64_t have = file_bytes >= data_start ? file_bytes - data_start : 0;
  const long long hs = local ? 0 : mi.HeaderSize();  // -1: the data are the file's last bytes
  std::ostringstream dx;
  for (int a = 0; a < nd; ++a) dx << (a ? " x " : "") << mi.DimSize(a);
  std::ostringstream head;
  if (local)
    head << "ElementDataFile = LOCAL: the data after the header hold " << have << " bytes; DimSize ";
  else
    head << "ElementDataFile '" << name << "' holds " << have << " bytes; DimSize ";
  head << dx.str() << " of ElementType " << type_name << " (" << type_bytes << " byte" << (type_bytes > 1 ? "s" : "") << " each"
       << (channels > 1 ? ", " + std::to_string(channels) + " channels" : std::string()) << ") needs ";
  const std::uint64_t want = (hs > 0 ? std::uint64_t(hs) : 0) + need;
  const bool bad = hs == -1 ? have < need : have != want;
  if (bad) {
    std::string m = head.str();
    if (hs > 0)
      m += "HeaderSize = " + std::to_string(hs) + " + " + std::to_string(need) + " = " + std::to_string(want) + " bytes";
    else
      m += std::to_string(need) + " bytes";
    m += have < want ? " (voxel data truncated)" : " (the file is longer: is ElementType or DimSize wrong?)";
    fail(path, m);
  }
}

// The header field that gave the direction matrix, for messages.
std::string direction_field(const std::string& reader) {
  if (reader == "itk:MetaImageIO") return fields_of("MetaImageIO").direction;
  if (reader == "itk:NiftiImageIO") return fields_of("NiftiImageIO").direction;
  return fields_of("teem").direction;  // NRRD, ITK or teem
}

// D must be orthonormal (check_direction); also notes whether it is the identity.
void finish_direction(Volume& v) {
  check_direction(v.path, v.direction, direction_field(v.reader));
  const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  v.direction_is_identity = true;
  for (int i = 0; i < 9; ++i)
    if (std::abs(v.direction[std::size_t(i)] - id[i]) > 1e-6) v.direction_is_identity = false;
}

// The gzipped-NIfTI reader does not report a short stream: count the bytes (gzread reads
// plain files too) and compare with vox_offset + the voxel bytes the header promises.
void check_nifti_length(const std::string& path, std::size_t data_bytes) {
  gzFile gz = gzopen(path.c_str(), "rb");
  if (!gz) fail(path, "cannot open");
  std::vector<unsigned char> buf(1 << 16);
  std::uint64_t total = 0;
  int got = 0;
  std::int32_t sizeof_hdr = 0;
  double vox_offset = 0;
  std::vector<unsigned char> head;
  while ((got = gzread(gz, buf.data(), unsigned(buf.size()))) > 0) {
    if (head.size() < 544) head.insert(head.end(), buf.begin(), buf.begin() + std::min(got, 544));
    total += std::uint64_t(got);
  }
  gzclose(gz);
  if (head.size() >= 348) {
    std::memcpy(&sizeof_hdr, head.data(), 4);
    if (sizeof_hdr == 348) {
      float f;
      std::memcpy(&f, head.data() + 108, 4);
      vox_offset = f;
    } else if (sizeof_hdr == 540 && head.size() >= 176) {
      std::int64_t o;
      std::memcpy(&o, head.data() + 168, 8);
      vox_offset = double(o);
    }
  }
  if (double(total) < vox_offset + double(data_bytes))
    fail(path, "voxel data truncated: the header promises " + std::to_string(data_bytes) +
                   " bytes after offset " + std::to_string(std::uint64_t(vox_offset)) +
                   ", the (decompressed) file holds " + std::to_string(total) + " bytes in all");
}

// NIfTI's orientation fields go to ITK's matrix code, which aborts the process on a
// non-finite element (vnl_matrix: "matrix has non-finite elements", abort()): check them
// here, before ITK reads the header. NIfTI-1 (348-byte header, floats) and NIfTI-2 (540,
// doubles), either byte order, plain or gzipped.
void check_nifti_header(const std::string& path) {
  gzFile gz = gzopen(path.c_str(), "rb");
  if (!gz) fail(path, "cannot open");
  unsigned char h[540] = {};
  const int got = gzread(gz, h, sizeof h);
  gzclose(gz);
  if (got < 348) return;  // ITK refuses it itself
  // Which header: the magic, as the NIfTI library decides (it does not trust sizeof_hdr),
  // else a 348 size field (Analyze 7.5). Byte order: dim[0] must be 1..7, as the library checks.
  const bool two = got >= 540 && (std::memcmp(h + 4, "n+2", 4) == 0 || std::memcmp(h + 4, "ni2", 4) == 0);
  std::int32_t size = 0;
  std::memcpy(&size, h, 4);
  const bool one = std::memcmp(h + 344, "n+1", 4) == 0 || std::memcmp(h + 344, "ni1", 4) == 0 || size == 348 ||
                   size == std::int32_t(__builtin_bswap32(348));
  if (!two && !one) return;
  bool swap = false;
  if (two) {
    std::int64_t d0;
    std::memcpy(&d0, h + 16, 8);
    swap = d0 < 1 || d0 > 7;
  } else {
    std::int16_t d0;
    std::memcpy(&d0, h + 40, 2);
    swap = d0 < 1 || d0 > 7;
  }
  auto number = [&](std::size_t at) -> double {
    if (two) {
      std::uint64_t u;
      std::memcpy(&u, h + at, 8);
      if (swap) u = __builtin_bswap64(u);
      double d;
      std::memcpy(&d, &u, 8);
      return d;
    }
    std::uint32_t u;
    std::memcpy(&u, h + at, 4);
    if (swap) u = __builtin_bswap32(u);
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  };
  const std::size_t w = two ? 8 : 4;
  struct Field {
    const char* name;
    std::size_t at1, at2;  // NIfTI-1, NIfTI-2 byte offsets
    int count;
  };
  const Field fields[] = {{"pixdim", 76, 104, 8},      {"quatern_b", 256, 352, 1}, {"quatern_c", 260, 360, 1},
                          {"quatern_d", 264, 368, 1},  {"qoffset_x", 268, 376, 1}, {"qoffset_y", 272, 384, 1},
                          {"qoffset_z", 276, 392, 1},  {"srow_x", 280, 400, 4},    {"srow_y", 296, 432, 4},
                          {"srow_z", 312, 464, 4}};
  for (const Field& f : fields)
    for (int i = 0; i < f.count; ++i) {
      const double v = number((two ? f.at2 : f.at1) + std::size_t(i) * w);
      if (!std::isfinite(v) || std::abs(v) > 1e30) {
        std::ostringstream m;
        m << "NIfTI header field '" << f.name << (f.count > 1 ? "[" + std::to_string(i) + "]" : std::string()) << "' is "
          << v << ": the orientation and voxel size must be finite and at most 1e30 in magnitude";
        fail(path, m.str());
      }
    }
}

void check_nrrd_length(const std::string& path, std::uint64_t need);

Volume load_itk(const std::string& path) {
  // Before any ITK reader looks at it (NiftiImageIO::CanReadFile already builds the matrices):
  // a file with a NIfTI header size must have finite orientation fields.
  check_nifti_header(path);
  // MetaIO prints its parse errors on std::cerr (from CanReadFile on): the header's one clear
  // line is the message, thrown below.
  QuietCerr quiet;
  itk::ImageIOBase::Pointer io;
  const itk::ImageIOBase::Pointer candidates[] = {
      itk::MetaImageIO::New().GetPointer(), itk::NrrdImageIO::New().GetPointer(),
      itk::NiftiImageIO::New().GetPointer()};
  for (const auto& c : candidates)
    if (c->CanReadFile(path.c_str())) {
      io = c;
      break;
    }
  if (!io)
    fail(path, "not a readable MetaImage (.mhd/.mha), NRRD (.nrrd/.nhdr) or NIfTI (.nii/.nii.gz) file");
  const std::string cls = io->GetNameOfClass();
  const VolumeFields fields = fields_of(cls);
  if (cls == "MetaImageIO") check_metaimage(path);
  io->SetFileName(path);
  io->ReadImageInformation();
  quiet.release();

  const unsigned nd = io->GetNumberOfDimensions();
  if (nd == 2) {
    const std::string field = cls == "MetaImageIO" ? "NDims" : cls == "NiftiImageIO" ? "dim[0]" : "dimension";
    fail(path, field + " 2: a 2-D image, not a volume (isotouch touches 3-D volumes: stack the slices, or "
                       "give the folder of a DICOM series)");
  }
  if (nd < 2 || nd > 4) fail(path, "has " + std::to_string(nd) + " dimensions (need 3)");
  if (io->GetNumberOfComponents() != 1)
    fail(path, "has " + std::to_string(io->GetNumberOfComponents()) +
                   " components per voxel (need a scalar volume)");
  std::array<std::uint64_t, 3> d{1, 1, 1};
  double sp[3] = {1, 1, 1}, org[3] = {0, 0, 0};
  Volume v;
  for (unsigned a = 0; a < std::min(nd, 3u); ++a) {
    d[a] = io->GetDimensions(a);
    sp[a] = io->GetSpacing(a);
    org[a] = io->GetOrigin(a);
    const auto dir = io->GetDirection(a);  // column a of the direction matrix
    for (unsigned r = 0; r < std::min<std::size_t>(dir.size(), 3); ++r)
      v.direction[r * 3 + a] = dir[r];
  }
  if (nd == 4 && io->GetDimensions(3) != 1)
    fail(path, "is a 4-D series with " + std::to_string(io->GetDimensions(3)) + " volumes (need one)");
  check_dims(path, d, fields.dims);
  set_spacing_origin(path, v, d, sp, org, fields);
  v.grid.dims = {int(d[0]), int(d[1]), int(d[2])};

  using CT = itk::IOComponentEnum;
  const CT ct = io->GetComponentType();
  v.component_type = itk::ImageIOBase::GetComponentTypeAsString(ct);
  const std::size_t n = v.grid.voxel_count();
  std::size_t bytes_per = io->GetComponentSize();
  switch (ct) {
    case CT::UCHAR: case CT::CHAR: case CT::USHORT: case CT::SHORT: case CT::UINT:
    case CT::INT: case CT::ULONG: case CT::LONG: case CT::ULONGLONG: case CT::LONGLONG:
    case CT::FLOAT: case CT::DOUBLE:
      break;
    default:
      fail(path, "unknown or unsupported voxel type '" + v.component_type + "'");
  }
  // Before any allocation: the file must hold the bytes its header promises (a 350-byte
  // .nii.gz may claim gigabytes) and the machine the memory.
  if (cls == "NiftiImageIO") check_nifti_length(path, n * bytes_per);
  if (cls == "NrrdImageIO") check_nrrd_length(path, n * bytes_per);
  check_memory(path, d, bytes_per, v.component_type);
  // The IO region must cover the whole image, or readers that stream read nothing.
  itk::ImageIORegion region(nd);
  for (unsigned a = 0; a < nd; ++a) {
    region.SetIndex(a, 0);
    region.SetSize(a, io->GetDimensions(a));
  }
  io->SetIORegion(region);
  // Some ITK readers (MetaImage, gzipped NIfTI) only warn on a short read and leave the
  // rest of the buffer untouched. Fill with a sentinel; if a tail still holds it, read
  // again with another: bytes that kept both sentinels were never written.
  std::vector<char> raw(n * bytes_per, char(0xA5));
  io->Read(raw.data());
  auto tail_run = [&](char sentinel) {
    std::size_t k = raw.size();
    while (k > 0 && raw[k - 1] == sentinel) --k;
    return k;
  };
  const std::size_t end_a = tail_run(char(0xA5));
  if (raw.size() - end_a >= bytes_per) {
    std::fill(raw.begin(), raw.end(), char(0x5A));
    io->Read(raw.data());
    const std::size_t end_b = tail_run(char(0x5A));
    const std::size_t written = std::max(end_a, end_b);
    if (written < raw.size())
      fail(path, "voxel data truncated: the header promises " + std::to_string(raw.size()) +
                     " bytes (" + std::to_string(d[0]) + " x " + std::to_string(d[1]) + " x " +
                     std::to_string(d[2]) + " " + v.component_type + "), the file provides " +
                     std::to_string(written));
  }
  switch (ct) {
    case CT::UCHAR: convert<std::uint8_t>(raw.data(), n, v.voxels); break;
    case CT::CHAR: convert<std::int8_t>(raw.data(), n, v.voxels); break;
    case CT::USHORT: convert<std::uint16_t>(raw.data(), n, v.voxels); break;
    case CT::SHORT: convert<std::int16_t>(raw.data(), n, v.voxels); break;
    case CT::UINT: convert<std::uint32_t>(raw.data(), n, v.voxels); break;
    case CT::INT: convert<std::int32_t>(raw.data(), n, v.voxels); break;
    case CT::ULONG: case CT::ULONGLONG:
      if (bytes_per == 8) convert<std::uint64_t>(raw.data(), n, v.voxels);
      else convert<std::uint32_t>(raw.data(), n, v.voxels);
      break;
    case CT::LONG: case CT::LONGLONG:
      if (bytes_per == 8) convert<std::int64_t>(raw.data(), n, v.voxels);
      else convert<std::int32_t>(raw.data(), n, v.voxels);
      break;
    case CT::FLOAT: convert<float>(raw.data(), n, v.voxels); break;
    case CT::DOUBLE: convert<double>(raw.data(), n, v.voxels); break;
    default: break;
  }
  v.reader = std::string("itk:") + io->GetNameOfClass();
  return v;
}

#ifdef ISOTOUCH_HAVE_TEEM
Volume load_teem(const std::string& path) {
  struct NrrdDel {
    void operator()(Nrrd* n) const { nrrdNuke(n); }
  };
  std::unique_ptr<Nrrd, NrrdDel> nin(nrrdNew()), nf(nrrdNew());
  auto biff_error = [] {
    char* e = biffGetDone(NRRD);
    std::string s = e ? e : "unknown teem error";
    free(e);
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    return s;
  };
  // The header alone first (teem skips the data): dims and memory are checked before the
  // data are read and allocated.
  {
    struct IoDel {
      void operator()(NrrdIoState* n) const { nrrdIoStateNix(n); }
    };
    std::unique_ptr<NrrdIoState, IoDel> head_only(nrrdIoStateNew());
    nrrdIoStateSet(head_only.get(), nrrdIoStateSkipData, AIR_TRUE);
    if (nrrdLoad(nin.get(), path.c_str(), head_only.get())) fail(path, "teem: " + biff_error());
    if (nin->dim == 2)
      fail(path, "dimension 2: a 2-D image, not a volume (isotouch touches 3-D volumes: stack the slices)");
    if (nin->dim < 2 || nin->dim > 3) fail(path, "has " + std::to_string(nin->dim) + " axes (need 3)");
    std::array<std::uint64_t, 3> hd{1, 1, 1};
    for (unsigned a = 0; a < nin->dim; ++a) hd[a] = nin->axis[a].size;
    check_dims(path, hd, fields_of("teem").dims);
    if (nin->type == nrrdTypeBlock) fail(path, "unknown or unsupported voxel type 'block'");
    check_nrrd_length(path, hd[0] * hd[1] * hd[2] * nrrdTypeSize[nin->type]);
    check_memory(path, hd, nrrdTypeSize[nin->type], airEnumStr(nrrdType, nin->type));
  }
  if (nrrdLoad(nin.get(), path.c_str(), nullptr)) fail(path, "teem: " + biff_error());
  if (nin->dim < 2 || nin->dim > 3) fail(path, "has " + std::to_string(nin->dim) + " axes (need 3)");
  std::array<std::uint64_t, 3> d{1, 1, 1};
  double sp[3] = {1, 1, 1}, org[3] = {0, 0, 0};
  Volume v;
  for (unsigned a = 0; a < nin->dim; ++a) {
    const NrrdAxisInfo& ax = nin->axis[a];
    d[a] = ax.size;
    if (AIR_EXISTS(ax.spacing)) {
      sp[a] = ax.spacing;
    } else if (nin->spaceDim > 0 && AIR_EXISTS(ax.spaceDirection[0])) {
      double len = 0;
      for (unsigned r = 0; r < nin->spaceDim; ++r) len += ax.spaceDirection[r] * ax.spaceDirection[r];
      sp[a] = std::sqrt(len);
      for (unsigned r = 0; r < std::min(nin->spaceDim, 3u); ++r)
        v.direction[r * 3 + a] = ax.spaceDirection[r] / sp[a];
    }
  }
  if (nin->spaceDim > 0)
    for (unsigned r = 0; r < std::min(nin->spaceDim, 3u); ++r)
      if (AIR_EXISTS(nin->spaceOrigin[r])) org[r] = nin->spaceOrigin[r];
  const VolumeFields fields = fields_of("teem");
  check_dims(path, d, fields.dims);
  set_spacing_origin(path, v, d, sp, org, fields);
  v.grid.dims = {int(d[0]), int(d[1]), int(d[2])};
  v.component_type = airEnumStr(nrrdType, nin->type);
  if (nin->type == nrrdTypeBlock) fail(path, "unknown or unsupported voxel type 'block'");
  if (nrrdConvert(nf.get(), nin.get(), nrrdTypeFloat)) fail(path, "teem: " + biff_error());
  const float* f = static_cast<const float*>(nf->data);
  v.voxels.assign(f, f + v.grid.voxel_count());
  v.reader = "teem:nrrdLoad";
  return v;
}
#endif

// A raw-encoded NRRD must hold the bytes its header promises: the attached data after the
// header's empty line, or one detached "data file". Checked before the voxels are allocated
// (other encodings and multi-file data: the size is known only once read; the memory cap and
// the read itself cover them).
void check_nrrd_length(const std::string& path, std::uint64_t need) {
  std::ifstream in(path, std::ios::binary);
  std::string line, encoding, data_file;
  std::uint64_t header_bytes = 0;
  bool ended = false;
  for (int n = 0; n < 4096 && std::getline(in, line); ++n) {
    header_bytes += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) {
      ended = true;
      break;
    }
    const auto value = [&](const char* key) {
      std::string v = line.substr(std::strlen(key));
      while (!v.empty() && v.front() == ' ') v.erase(v.begin());
      return v;
    };
    if (line.rfind("encoding:", 0) == 0) encoding = value("encoding:");
    if (line.rfind("data file:", 0) == 0 || line.rfind("datafile:", 0) == 0)
      data_file = value(line[4] == ' ' ? "data file:" : "datafile:");
  }
  const bool gzip = encoding == "gzip" || encoding == "gz";
  if (encoding != "raw" && !gzip) return;
  std::error_code ec;
  if (data_file.empty() && !ended) return;  // a detached header without a data file line: teem / ITK name it
  if (data_file.find(' ') != std::string::npos || data_file == "LIST") return;  // several files
  fs::path df(data_file.empty() ? path : data_file);
  if (df.is_relative() && !data_file.empty()) df = fs::path(path).parent_path() / df;
  const std::uint64_t offset = data_file.empty() ? header_bytes : 0;
  const std::string field = data_file.empty() ? "the data after the header" : "field 'data file' = '" + data_file + "'";
  if (!fs::exists(df, ec)) return;  // missing data file: the reader names it
  if (gzip) return check_inflated(path, field, df.string(), offset, need);
  const std::uint64_t size = fs::file_size(df, ec);
  if (ec) return;
  const std::uint64_t have = size - std::min(offset, size);
  if (have < need)
    fail(path, "voxel data truncated: " + field + (data_file.empty() ? " hold " : " holds ") + std::to_string(have) +
                   " bytes, the header (field 'sizes', 'type') promises " + std::to_string(need));
}

// NRRD "spacings:" as the header writes it: ITK and teem both put 1 mm in place of a
// "nan" (NRRD's "no spacing"), which for a scalar volume hides a broken header. Read the
// header text (up to the first empty line) and fail on a spacing that is not a positive
// finite number.
void check_nrrd_spacings(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  for (int n = 0; n < 4096 && std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) break;  // end of the header of a .nrrd
    if (line.rfind("data file:", 0) == 0 || line.rfind("datafile:", 0) == 0) {
      std::string df = line.substr(line.find(':') + 1);
      while (!df.empty() && df.front() == ' ') df.erase(df.begin());
      fs::path p(df);
      if (p.is_relative()) p = fs::path(path).parent_path() / p;
      std::error_code ec;
      if (df.find(' ') == std::string::npos && df != "LIST" && fs::exists(p, ec))
        require_regular_file(p.string(), "the voxel data of " + path + " (field 'data file') must be a regular file");
      continue;
    }
    if (line.rfind("spacings:", 0) != 0) continue;
    std::istringstream t(line.substr(9));
    std::string tok;
    for (int a = 0; t >> tok; ++a) {
      char* end = nullptr;
      const double d = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(d) || d <= 0.0)
        fail(path, "field 'spacings' along axis " + std::to_string(a) + " is '" + tok +
                       "' (must be a positive number of mm; ITK and teem would silently use 1 mm)");
    }
  }
}

}  // namespace

// ITK and teem messages carry source locations and call chains; keep the last, most
// specific line, without the "ITK ERROR: Class(0x...): " prefix.
std::string itk_reason(std::string msg) {
  const auto e = msg.find("ITK ERROR: ");
  if (e != std::string::npos) {
    msg = msg.substr(e + 11);
    const auto colon = msg.find("): ");
    if (colon != std::string::npos && colon < 64) msg = msg.substr(colon + 3);
  }
  while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
  const auto nl = msg.rfind('\n');
  if (nl != std::string::npos) msg = msg.substr(nl + 1);
  if (msg.find("Unknown component type") != std::string::npos)
    msg = "unknown or unsupported voxel type (" + msg + ")";
  return msg;
}

// D must be orthonormal (|D^T D - I| <= 1e-3 per entry): world = origin + D (spacing *
// index) and Volume::to_grid use D^T as the inverse. A singular D (TransformMatrix all
// zeros) would put every point at the origin, a scaling one would rescale the volume
// behind the spacing's back, a NaN one would put every point nowhere: all errors naming
// the field and the values.
void check_direction(const std::string& path, const std::array<double, 9>& D, const std::string& field) {
  double worst = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += D[std::size_t(k * 3 + i)] * D[std::size_t(k * 3 + j)];
      const double e = std::abs(dot - (i == j ? 1.0 : 0.0));
      worst = e == e ? std::max(worst, e) : std::numeric_limits<double>::infinity();
    }
  if (worst <= 1e-3) return;
  std::ostringstream s;
  s << "field '" << field << "' gives the direction matrix (columns: index axes) [[" << D[0] << ", " << D[1] << ", "
    << D[2] << "], [" << D[3] << ", " << D[4] << ", " << D[5] << "], [" << D[6] << ", " << D[7] << ", " << D[8]
    << "]], which is not orthonormal (max |D^T D - I| = " << worst
    << ", the limit is 0.001): the direction cosines must be finite, unit and perpendicular (voxel size goes in the "
       "spacing)";
  fail(path, s.str());
}

void check_volume_limits(const std::string& path, const std::array<std::uint64_t, 3>& dims,
                         const std::array<double, 3>& spacing_mm, const std::array<double, 3>& origin_mm,
                         std::uint64_t stored_bytes_per_voxel, const std::string& type, const VolumeFields& fields) {
  check_dims(path, dims, fields.dims);
  check_spacing_origin(path, dims, spacing_mm.data(), origin_mm.data(), fields);
  check_memory(path, dims, stored_bytes_per_voxel, type);
}

std::uint64_t memory_budget_bytes() {
  std::uint64_t have = 0;
  const auto take = [&have](std::uint64_t b) {
    if (b > 0 && (have == 0 || b < have)) have = b;
  };
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  if (pages > 0 && page > 0) take(std::uint64_t(pages) * std::uint64_t(page));
  rlimit as{};
  if (::getrlimit(RLIMIT_AS, &as) == 0 && as.rlim_cur != RLIM_INFINITY) take(std::uint64_t(as.rlim_cur));
  std::ifstream cg("/sys/fs/cgroup/memory.max");  // cgroup v2; "max" = no limit
  std::uint64_t limit = 0;
  if (cg >> limit) take(limit);
  return have;
}

void require_regular_file(const std::string& path, const std::string& why) {
  const std::string no = not_a_regular_file(path);
  if (!no.empty()) fail(path, no + ": " + why);
}

Volume load_volume(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) {
    // A folder is a DICOM series (its slices): what the reader chose or ignored is said on stderr.
    DicomSeriesInfo info;
    Volume v = load_dicom_series(path, "", &info);
    for (const auto& note : info.notes) std::cerr << "isotouch: note: " << path << ": " << note << "\n";
    return v;
  }
  require_regular_file(path, "a volume is read from a regular file or a DICOM series folder");
  if (is_nrrd(path)) check_nrrd_spacings(path);
  Volume v;
  try {
    v = load_itk(path);
  } catch (const VolumeError&) {
    throw;
  } catch (const std::exception& e) {
    const std::string msg = itk_reason(e.what());
#ifdef ISOTOUCH_HAVE_TEEM
    if (is_nrrd(path)) {
      try {
        v = load_teem(path);
      } catch (const VolumeError& te) {
        fail(path, "ITK could not read it (" + msg + ") and neither could teem (" +
                       itk_reason(std::string(te.what()).substr(path.size() + 2)) + ")");
      }
    } else
#endif
      fail(path, msg);
  }
  v.path = path;
  finish_direction(v);
  v.update_stats();
  return v;
}

std::vector<std::pair<std::string, std::string>> header_text_fields(const std::string& path) {
  std::vector<std::pair<std::string, std::string>> out;
  const std::string l = lower(path);
  const bool nrrd = is_nrrd(path), nifti = ends_with(l, ".nii") || ends_with(l, ".nii.gz");
  if (!nrrd && !nifti) return out;
  try {
    if (nifti) check_nifti_header(path);  // (ITK's matrix code aborts on bad orientation fields)
    QuietCerr quiet;
    itk::ImageIOBase::Pointer io;
    if (nrrd) io = itk::NrrdImageIO::New().GetPointer();
    else io = itk::NiftiImageIO::New().GetPointer();
    io->SetFileName(path);
    io->ReadImageInformation();
    const itk::MetaDataDictionary& d = io->GetMetaDataDictionary();
    for (const std::string& key : d.GetKeys()) {
      std::string value;
      if (!itk::ExposeMetaData<std::string>(d, key, value) || value.empty()) continue;
      if (nifti && key != "descrip" && key != "intent_name" && key != "aux_file") continue;
      if (nrrd && key.rfind("ITK_", 0) == 0) continue;  // ITK's own, not the file's
      out.emplace_back(nrrd && key == "NRRD_content" ? "content" : key, value);
    }
  } catch (const std::exception&) {
    out.clear();  // unreadable: load_volume says why
  }
  return out;
}

}  // namespace isotouch::io
