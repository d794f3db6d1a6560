#include "isotouch/service/edit_mirror.h"

#include "isotouch/core/brick_field.h"

#include <algorithm>

namespace isotouch::service {

EditMirror::EditMirror(const engine::Volume& v) : v_(v) {}

session::EditListener EditMirror::listener(const session::EditSession& es) {
  return [this, &es](const session::EditEvent& e, const session::EditOutcome& out, session::EditSource) {
    if (!out.error.empty()) return;
    const bool brush = e.kind == session::EditEvent::Kind::kBrush;
    copy_bricks(es.volume(), brush ? out.brush.dirty : out.restored);
  };
}

void EditMirror::copy_bricks(const engine::Volume& from, const std::vector<std::uint32_t>& ids) {
  const auto& n = v_.grid.dims;
  const auto nbx = std::uint32_t((n[0] + 7) / 8), nby = std::uint32_t((n[1] + 7) / 8);
  std::lock_guard<std::mutex> lock(mu_);
  ++edits_;
  for (std::uint32_t id : ids) {
    VoxelBox b;
    b.lo = {8 * int(id % nbx), 8 * int(id / nbx % nby), 8 * int(id / (nbx * nby))};
    for (int a = 0; a < 3; ++a) b.hi[std::size_t(a)] = std::min(n[std::size_t(a)], b.lo[std::size_t(a)] + 8);
    core::copy_brick_voxels(v_.grid, id, from.voxels.data(), v_.voxels.data());
    changed_.add(b);
  }
}

engine::Volume EditMirror::volume() const {
  engine::Volume out;
  {
    std::lock_guard<std::mutex> lock(mu_);
    out = v_;
  }
  out.update_stats();
  return out;
}

VoxelBox EditMirror::take_changed() const {
  std::lock_guard<std::mutex> lock(mu_);
  const VoxelBox b = changed_;
  changed_ = VoxelBox{};
  return b;
}

void EditMirror::copy_box(const VoxelBox& b, float* out) const {
  const std::size_t nx = std::size_t(v_.grid.dims[0]), ny = std::size_t(v_.grid.dims[1]);  // fixed: no lock
  const long row = b.hi[0] - b.lo[0];
  for (int z = b.lo[2]; z < b.hi[2]; ++z) {
    std::lock_guard<std::mutex> lock(mu_);
    for (int y = b.lo[1]; y < b.hi[1]; ++y) {
      const std::size_t at = (std::size_t(z) * ny + std::size_t(y)) * nx + std::size_t(b.lo[0]);
      out = std::copy_n(v_.voxels.begin() + long(at), row, out);
    }
  }
}

void EditMirror::restore_changed(const VoxelBox& box) const {
  std::lock_guard<std::mutex> lock(mu_);
  changed_.add(box);
}

long EditMirror::edits() const {
  std::lock_guard<std::mutex> lock(mu_);
  return edits_;
}

}  // namespace isotouch::service
