#include "isotouch/service/edit_mirror.h"

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
    for (int z = b.lo[2]; z < b.hi[2]; ++z)
      for (int y = b.lo[1]; y < b.hi[1]; ++y) {
        const std::size_t at = (std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(b.lo[0]);
        std::copy_n(from.voxels.begin() + long(at), b.hi[0] - b.lo[0], v_.voxels.begin() + long(at));
      }
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

VoxelBox EditMirror::take_changed(engine::Volume& out) const {
  std::lock_guard<std::mutex> lock(mu_);
  out = v_;
  const VoxelBox b = changed_;
  changed_ = VoxelBox{};
  return b;
}

long EditMirror::edits() const {
  std::lock_guard<std::mutex> lock(mu_);
  return edits_;
}

}  // namespace isotouch::service
