// igtl_test_sender.h - an IMAGE built the way a sender (Slicer, PLUS) builds it from a loaded
// file, with the OpenIGTLink library: what test_service and igtl_send_image send. Written
// here, apart from service/, so a convention error on the receiving side cannot cancel out.
#pragma once
#include <cstdint>
#include <vector>

#include <igtlImageMessage.h>

#include "isotouch/engine/volume.h"

namespace isotouch::test {

inline std::vector<std::uint8_t> bytes_of(igtl::MessageBase* m) {
  m->Pack();
  const auto* p = static_cast<const std::uint8_t*>(m->GetPackPointer());
  return {p, p + m->GetPackSize()};
}

/// An IMAGE as a sender builds it from a loaded file: RAS, its centre as the position,
/// int16 voxels in the library's default (big-endian) or little-endian byte order.
inline std::vector<std::uint8_t> image_of(const engine::Volume& v, int endian, const char* name = "Head") {
  igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
  int dims[3] = {v.grid.dims[0], v.grid.dims[1], v.grid.dims[2]};
  float sp[3] = {float(v.grid.spacing_m.x * 1e3), float(v.grid.spacing_m.y * 1e3), float(v.grid.spacing_m.z * 1e3)};
  m->SetDimensions(dims);
  m->SetSpacing(sp);
  m->SetScalarType(igtl::ImageMessage::TYPE_INT16);
  m->SetEndian(endian);
  m->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
  m->SetDeviceName(name);
  m->AllocateScalars();
  // The centre, LPS -> RAS: the middle between the first and last voxel centres.
  const core::Vec3 c = v.index_to_physical({(dims[0] - 1) / 2.0, (dims[1] - 1) / 2.0, (dims[2] - 1) / 2.0});
  igtl::Matrix4x4 mat;
  igtl::IdentityMatrix(mat);
  for (int r = 0; r < 3; ++r) {
    const double f = r < 2 ? -1.0 : 1.0;
    for (int a = 0; a < 3; ++a) mat[r][a] = float(f * v.direction[std::size_t(3 * r + a)]);
  }
  mat[0][3] = float(-c.x * 1e3);
  mat[1][3] = float(-c.y * 1e3);
  mat[2][3] = float(c.z * 1e3);
  m->SetMatrix(mat);
  auto* out = static_cast<std::uint8_t*>(m->GetScalarPointer());
  for (std::size_t i = 0; i < v.voxels.size(); ++i) {
    const auto s = std::uint16_t(std::int16_t(v.voxels[i]));
    const bool big = endian == igtl::ImageMessage::ENDIAN_BIG;
    out[2 * i] = std::uint8_t(big ? s >> 8 : s & 0xff);
    out[2 * i + 1] = std::uint8_t(big ? s & 0xff : s >> 8);
  }
  return bytes_of(m);
}

/// What the upstream Imager examples send: 256 x 256 x 1 uint8 (zeros here).
inline std::vector<std::uint8_t> single_slice(const char* name = "ImagerClient") {
  igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
  int dims[3] = {256, 256, 1};
  m->SetDimensions(dims);
  m->SetScalarType(igtl::ImageMessage::TYPE_UINT8);
  m->SetDeviceName(name);
  m->AllocateScalars();
  return bytes_of(m);
}

}  // namespace isotouch::test
