#include "isotouch/service/image_volume.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <sstream>

#include "isotouch/io/volume_io.h"

namespace isotouch::service {
namespace {

[[noreturn]] void refuse(const std::string& device, const std::string& why) {
  throw engine::VolumeError("igtl:" + device + ": " + why);
}

template <class T>
T take(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

/// The voxels as float, x fastest (the wire's order), in the image's own byte order.
void copy_voxels(igtl::ImageMessage& image, engine::Volume& v) {
  const auto* p = static_cast<const unsigned char*>(image.GetScalarPointer());
  const bool little_host = [] { const std::uint16_t one = 1; unsigned char c; std::memcpy(&c, &one, 1); return c == 1; }();
  const bool swap = (image.GetEndian() == igtl::ImageMessage::ENDIAN_LITTLE) != little_host;
  const std::size_t n = v.grid.voxel_count();
  v.voxels.resize(n);
  using I = igtl::ImageMessage;
  for (std::size_t i = 0; i < n; ++i) {
    switch (image.GetScalarType()) {
      case I::TYPE_INT8: v.voxels[i] = float(take<std::int8_t>(p + i, swap)); break;
      case I::TYPE_UINT8: v.voxels[i] = float(take<std::uint8_t>(p + i, swap)); break;
      case I::TYPE_INT16: v.voxels[i] = float(take<std::int16_t>(p + 2 * i, swap)); break;
      case I::TYPE_UINT16: v.voxels[i] = float(take<std::uint16_t>(p + 2 * i, swap)); break;
      case I::TYPE_INT32: v.voxels[i] = float(take<std::int32_t>(p + 4 * i, swap)); break;
      case I::TYPE_UINT32: v.voxels[i] = float(take<std::uint32_t>(p + 4 * i, swap)); break;
      case I::TYPE_FLOAT32: v.voxels[i] = take<float>(p + 4 * i, swap); break;
      default: v.voxels[i] = float(take<double>(p + 8 * i, swap)); break;
    }
  }
}

const char* type_name(int t) {
  using I = igtl::ImageMessage;
  switch (t) {
    case I::TYPE_INT8: return "char";
    case I::TYPE_UINT8: return "unsigned_char";
    case I::TYPE_INT16: return "short";
    case I::TYPE_UINT16: return "unsigned_short";
    case I::TYPE_INT32: return "int";
    case I::TYPE_UINT32: return "unsigned_int";
    case I::TYPE_FLOAT32: return "float";
    default: return "double";
  }
}

/// Dimensions: whole 3-D images only, within io's limits.
void check_size(igtl::ImageMessage& image, const std::string& dev, engine::Volume& v) {
  int size[3], sub[3], off[3];
  image.GetDimensions(size);
  image.GetSubVolume(sub, off);
  std::ostringstream d;
  d << size[0] << " x " << size[1] << " x " << size[2];
  for (int a = 0; a < 3; ++a)
    if (size[a] < 2)
      refuse(dev, "image is " + d.str() + " voxels: a single slice (or line) is not a volume; send a 3-D image of "
                  "at least 2 voxels along each axis");
  if (sub[0] != size[0] || sub[1] != size[1] || sub[2] != size[2])
    refuse(dev, "image is a sub-volume of a " + d.str() + " image; only whole images are taken");
  if (image.GetNumComponents() != 1)
    refuse(dev, "image has " + std::to_string(image.GetNumComponents()) + " components per voxel; only scalar images are taken");
  const std::uint64_t total = std::uint64_t(size[0]) * std::uint64_t(size[1]) * std::uint64_t(size[2]);
  if (total > io::kMaxVoxels) refuse(dev, "image is " + d.str() + " voxels, past the limit of " + std::to_string(io::kMaxVoxels));
  v.grid.dims = {size[0], size[1], size[2]};
}

/// Spacing, direction and origin (LPS, m) from the header's spacing, normals and centre.
void place(igtl::ImageMessage& image, const std::string& dev, engine::Volume& v) {
  float sp[3];
  image.GetSpacing(sp);
  igtl::Matrix4x4 m;
  image.GetMatrix(m);
  const double flip[3] = {image.GetCoordinateSystem() == igtl::ImageMessage::COORDINATE_LPS ? 1.0 : -1.0,
                          image.GetCoordinateSystem() == igtl::ImageMessage::COORDINATE_LPS ? 1.0 : -1.0, 1.0};
  double half_mm[3] = {0, 0, 0};  // D (spacing * (dims - 1) / 2), the header's frame
  for (int a = 0; a < 3; ++a) {
    if (!(std::isfinite(sp[a]) && sp[a] > 0))
      refuse(dev, "spacing along axis " + std::to_string(a) + " is " + std::to_string(sp[a]) + " mm (must be positive)");
    if (double(v.grid.dims[a] - 1) * sp[a] * 1e-3 > io::kMaxExtentM)
      refuse(dev, "extent along axis " + std::to_string(a) + " is past the limit of " + std::to_string(io::kMaxExtentM) + " m");
    for (int r = 0; r < 3; ++r) half_mm[r] += double(m[r][a]) * double(sp[a]) * double(v.grid.dims[a] - 1) / 2.0;
  }
  double worst = 0;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      double dot = 0;
      for (int r = 0; r < 3; ++r) dot += double(m[r][a]) * double(m[r][b]);
      worst = std::max(worst, std::abs(dot - (a == b ? 1.0 : 0.0)));
    }
  if (!(worst <= 1e-3))
    refuse(dev, "direction columns are not unit and perpendicular (max |D^T D - I| = " + std::to_string(worst) + ")");
  double origin_mm[3];
  for (int r = 0; r < 3; ++r) {
    origin_mm[r] = flip[r] * (double(m[r][3]) - half_mm[r]);
    if (!(std::isfinite(origin_mm[r]) && std::abs(origin_mm[r]) * 1e-3 <= io::kMaxOriginM))
      refuse(dev, "image centre along axis " + std::to_string(r) + " is " + std::to_string(m[r][3]) +
                      " mm (must be finite, within " + std::to_string(io::kMaxOriginM) + " m)");
    for (int a = 0; a < 3; ++a) v.direction[std::size_t(3 * r + a)] = flip[r] * double(m[r][a]);
  }
  v.grid.spacing_m = {sp[0] * 1e-3, sp[1] * 1e-3, sp[2] * 1e-3};
  v.grid.origin_m = {origin_mm[0] * 1e-3, origin_mm[1] * 1e-3, origin_mm[2] * 1e-3};
  v.direction_is_identity = true;
  for (int i = 0; i < 9; ++i)
    if (std::abs(v.direction[std::size_t(i)] - (i % 4 == 0 ? 1.0 : 0.0)) > 1e-6) v.direction_is_identity = false;
}

}  // namespace

namespace {
engine::Volume read_volume(igtl::ImageMessage& image, const std::string& dev) {
  engine::Volume v;
  check_size(image, dev, v);
  place(image, dev, v);
  v.path = "igtl:" + dev;
  v.reader = "igtl:IMAGE";
  v.component_type = type_name(image.GetScalarType());
  copy_voxels(image, v);
  v.update_stats();
  return v;
}
}  // namespace

engine::Volume volume_from_image(igtl::ImageMessage& image) {
  const std::string dev = image.GetDeviceName();
  std::string lower = dev;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (lower.find("label") != std::string::npos)
    refuse(dev, "the device name says label map; a label map is taken only after a LBMETA naming it (send a "
                "scalar image, or the LBMETA first)");
  return read_volume(image, dev);
}

engine::Volume label_map_from_image(igtl::ImageMessage& image) {
  const std::string dev = image.GetDeviceName();
  using I = igtl::ImageMessage;
  const int t = image.GetScalarType();
  if (t == I::TYPE_FLOAT32 || t == I::TYPE_FLOAT64)
    refuse(dev, std::string("a label map's scalar type is ") + type_name(t) +
                    "; label maps are integer images (char, short, int, signed or unsigned)");
  return read_volume(image, dev);
}

void VoxelBox::add(const VoxelBox& o) {
  if (o.empty()) return;
  if (empty()) {
    *this = o;
    return;
  }
  for (int a = 0; a < 3; ++a) {
    lo[std::size_t(a)] = std::min(lo[std::size_t(a)], o.lo[std::size_t(a)]);
    hi[std::size_t(a)] = std::max(hi[std::size_t(a)], o.hi[std::size_t(a)]);
  }
}

std::vector<std::uint8_t> pack_image(const engine::Volume& v, const std::string& device, const VoxelBox& box) {
  VoxelBox b = box;
  if (b.empty()) b.hi = {v.grid.dims[0], v.grid.dims[1], v.grid.dims[2]};
  const std::size_t nx = std::size_t(v.grid.dims[0]), ny = std::size_t(v.grid.dims[1]);
  return pack_image(v, device, b, [&](float* out) {
    for (int z = b.lo[2]; z < b.hi[2]; ++z)
      for (int y = b.lo[1]; y < b.hi[1]; ++y) {
        const std::size_t at = (std::size_t(z) * ny + std::size_t(y)) * nx + std::size_t(b.lo[0]);
        out = std::copy_n(v.voxels.begin() + long(at), b.hi[0] - b.lo[0], out);
      }
  });
}

std::vector<std::uint8_t> pack_image(const engine::Volume& v, const std::string& device, const VoxelBox& box,
                                     const std::function<void(float* out)>& fill) {
  igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
  int dims[3] = {v.grid.dims[0], v.grid.dims[1], v.grid.dims[2]};
  VoxelBox b = box;
  if (b.empty()) b.hi = {dims[0], dims[1], dims[2]};
  int size[3] = {b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]}, off[3] = {b.lo[0], b.lo[1], b.lo[2]};
  float sp[3] = {float(v.grid.spacing_m.x * 1e3), float(v.grid.spacing_m.y * 1e3), float(v.grid.spacing_m.z * 1e3)};
  m->SetDimensions(dims);
  m->SetSubVolume(size, off);
  m->SetSpacing(sp);
  m->SetScalarType(igtl::ImageMessage::TYPE_FLOAT32);
  m->SetEndian(igtl::ImageMessage::ENDIAN_LITTLE);
  m->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
  m->SetDeviceName(device.substr(0, 20).c_str());
  // Directions and centre, LPS [m] -> RAS [mm]: rows 0 and 1 change sign.
  const core::Vec3 c = v.index_to_physical({(dims[0] - 1) / 2.0, (dims[1] - 1) / 2.0, (dims[2] - 1) / 2.0});
  const double centre[3] = {-c.x * 1e3, -c.y * 1e3, c.z * 1e3};
  igtl::Matrix4x4 mat;
  igtl::IdentityMatrix(mat);
  for (int r = 0; r < 3; ++r) {
    for (int a = 0; a < 3; ++a) mat[r][a] = float((r < 2 ? -1.0 : 1.0) * v.direction[std::size_t(3 * r + a)]);
    mat[r][3] = float(centre[r]);
  }
  m->SetMatrix(mat);
  m->AllocateScalars();
  static_assert(std::endian::native == std::endian::little, "the IMAGE is announced little-endian");
  fill(static_cast<float*>(m->GetScalarPointer()));
  igtl::TimeStamp::Pointer now = igtl::TimeStamp::New();
  now->GetTime();
  m->SetTimeStamp(now);
  m->Pack();
  const auto* p = static_cast<const std::uint8_t*>(m->GetPackPointer());
  return {p, p + m->GetPackSize()};
}

}  // namespace isotouch::service
