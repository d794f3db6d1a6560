// sparse_lists.cpp - the work lists of the sparse chain's list strategy (engine/sparse_chain.h):
// which quads each pass computes so that the host reads exact candidate ranges and samples.
#include <algorithm>
#include <array>
#include <cstring>

#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/sparse_chain.h"

namespace isotouch::engine::sparse {

namespace {
int ceil4(int v) { return (v + 3) / 4 * 4; }
int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
}  // namespace

std::vector<Extent> list_extents(const Plan& plan) {
  const std::size_t n = plan.ops.size();
  std::vector<Extent> e(n);
  // What the host reads of the last filter's output: the candidate range (8 b - 1 ..
  // 8 b + 8) and the gradient's input for the 9^3 samples (8 b - 1 .. 8 b + 9).
  Extent need;
  need.lo = {1, 1, 1};
  need.hi = {2, 2, 2};
  for (std::size_t k = n; k-- > 0;) {
    Extent out = need;
    out.lo[0] = ceil4(out.lo[0]);
    out.hi[0] = ceil4(out.hi[0]);
    e[k] = out;
    need = out;
    need.lo[std::size_t(plan.ops[k].axis)] += plan.ops[k].radius;
    need.hi[std::size_t(plan.ops[k].axis)] += plan.ops[k].radius;
  }
  return e;
}

WorkList make_work_list(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                        const std::string& what) {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const int qx = (nx + int(ISOTOUCH_DENSE_VOXELS) - 1) / int(ISOTOUCH_DENSE_VOXELS);
  if (std::uint64_t(ny) * std::uint64_t(nz) >= (1u << 24) ||
      std::uint64_t(qx) * ISOTOUCH_LIST_PACK >= (1u << 24))
    throw VolumeError(what + ": sparse chain: " + std::to_string(nx) + "x" + std::to_string(ny) + "x" +
                      std::to_string(nz) + " is too large for the work lists (rows and quads below 2^24)");
  const auto nb = core::brick_counts(grid);
  const std::size_t nbx = std::size_t(nb[0]), nby = std::size_t(nb[1]), nbz = std::size_t(nb[2]);
  std::vector<std::uint8_t> mark(nbx * nby * nbz, 0), layer(nbz, 0);
  for (std::uint32_t id : candidates) {
    mark[id] = 1;
    layer[id / (nbx * nby)] = 1;
  }
  // Brick layers whose extent covers index i along axis a: 8 b - lo <= i <= 8 b + 7 + hi.
  auto bricks_at = [&](int i, int a) {
    const int b0 = std::max(floor_div(i - 7 - e.hi[std::size_t(a)] + 7, 8), 0);
    const int b1 = std::min(floor_div(i + e.lo[std::size_t(a)], 8), nb[std::size_t(a)] - 1);
    return std::pair{b0, b1};
  };
  WorkList w;
  w.z_first.assign(std::size_t(nz) + 1, 0);
  std::vector<std::uint8_t> col(nbx, 0);
  std::vector<std::pair<int, int>> runs;  // quads [first, last] of the current row class
  for (int z = 0; z < nz; ++z) {
    const auto [bz0, bz1] = bricks_at(z, 2);
    bool any = false;  // a slice no candidate's extent reaches has no units (few candidates: most)
    for (int bz = bz0; bz <= bz1; ++bz) any = any || layer[std::size_t(bz)];
    if (!any) {
      w.z_first[std::size_t(z) + 1] = std::uint32_t(w.unit_count());
      continue;
    }
    std::pair<int, int> prev{-1, -2};
    for (int y = 0; y < ny; ++y) {
      const auto by = bricks_at(y, 1);
      if (by != prev) {  // rows with the same brick rows share their runs
        prev = by;
        std::fill(col.begin(), col.end(), std::uint8_t(0));
        for (int bz = bz0; bz <= bz1; ++bz)
          for (int b = by.first; b <= by.second; ++b) {
            const std::uint8_t* m = mark.data() + (std::size_t(bz) * std::size_t(nb[1]) + std::size_t(b)) * std::size_t(nb[0]);
            for (int bx = 0; bx < nb[0]; ++bx) col[std::size_t(bx)] |= m[bx];
          }
        runs.clear();
        for (int bx = 0; bx < nb[0]; ++bx) {
          if (!col[std::size_t(bx)]) continue;
          const int q0 = std::max(8 * bx - e.lo[0], 0) / 4;
          const int q1 = std::min(8 * bx + 7 + e.hi[0], nx - 1) / 4;
          if (!runs.empty() && q0 <= runs.back().second + 1)
            runs.back().second = std::max(runs.back().second, q1);
          else
            runs.push_back({q0, q1});
        }
      }
      const float row = float(y + ny * z);
      for (const auto& [q0, q1] : runs)
        for (int q = q0; q <= q1; q += int(ISOTOUCH_LIST_QUADS)) {
          const int n = std::min(q1 - q + 1, int(ISOTOUCH_LIST_QUADS));
          w.units.push_back(row);
          w.units.push_back(float(q * int(ISOTOUCH_LIST_PACK) + n));
          w.quads += std::uint64_t(n);
        }
    }
    w.z_first[std::size_t(z) + 1] = std::uint32_t(w.unit_count());
  }
  return w;
}

bool fusable(const Plan& plan, const core::Grid& grid) {
  if (plan.ops.size() != 3 || grid.dims[0] % int(ISOTOUCH_DENSE_VOXELS) != 0) return false;
  for (int a = 0; a < 3; ++a) {
    const Op& op = plan.ops[std::size_t(a)];
    if (op.kind != OpKind::kGauss || op.axis != a || op.radius > int(ISOTOUCH_FUSED_MAX_RADIUS)) return false;
  }
  return true;
}

namespace {
/// What both column-list builders read per slice: which rows of each brick column the
/// candidates' stencil extents cover in slice z, and from that, which rows of a quad column.
class CandidateRows {
 public:
  /// Throws VolumeError when `units_per_slice_column` x columns x slices or the rows do not fit
  /// the list's 2^24 packing.
  CandidateRows(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                const std::string& what, std::uint64_t units_per_slice_column)
      : e_(e), nb_(core::brick_counts(grid)), nx_(grid.dims[0]), ny_(grid.dims[1]),
        nbx_(std::size_t(nb_[0])), nby_(std::size_t(nb_[1])),
        mark_(nbx_ * nby_ * std::size_t(nb_[2]), 0), rows_of_bx_(nbx_ * std::size_t(ny_), 0) {
    const int nz = grid.dims[2], qx = quad_columns();
    if (units_per_slice_column * std::uint64_t(qx) * std::uint64_t(nz) >= (1u << 24) ||
        std::uint64_t(ny_) * ISOTOUCH_LIST_PACK >= (1u << 24))
      throw VolumeError(what + ": sparse chain: " + std::to_string(nx_) + "x" + std::to_string(ny_) + "x" +
                        std::to_string(nz) + " is too large for the column lists (columns and rows below 2^24)");
    layer_.assign(std::size_t(nb_[2]), 0);
    int bx_lo = nb_[0], bx_hi = -1;
    for (std::uint32_t id : candidates) {
      mark_[id] = 1;
      layer_[id / (nbx_ * nby_)] = 1;
      bx_lo = std::min(bx_lo, int(id % nbx_));
      bx_hi = std::max(bx_hi, int(id % nbx_));
    }
    // The quad columns any candidate's extent reaches: [q_lo, q_hi) (empty without one).
    q_lo_ = bx_hi < 0 ? 0 : std::max(8 * bx_lo - e.lo[0], 0) / 4;
    q_hi_ = bx_hi < 0 ? 0 : std::min(8 * bx_hi + 7 + e.hi[0], nx_ - 1) / 4 + 1;
  }
  /// Quad columns [q_lo, q_hi): outside them no candidate's extent reaches.
  int q_lo() const { return q_lo_; }
  int q_hi() const { return q_hi_; }
  /// Whether some candidate's extent reaches slice z (else its rows are all 0).
  bool reaches(int z) const {
    const auto [bz0, bz1] = bricks_at(z, 2);
    for (int bz = bz0; bz <= bz1; ++bz)
      if (layer_[std::size_t(bz)]) return true;
    return false;
  }
  int quad_columns() const { return (nx_ + int(ISOTOUCH_DENSE_VOXELS) - 1) / int(ISOTOUCH_DENSE_VOXELS); }

  /// Slice z: the rows each brick column's candidates cover.
  void mark_slice(int z) {
    const auto [bz0, bz1] = bricks_at(z, 2);
    std::fill(rows_of_bx_.begin(), rows_of_bx_.end(), std::uint8_t(0));
    for (int bz = bz0; bz <= bz1; ++bz)
      for (std::size_t by = 0; by < nby_; ++by)
        for (std::size_t bx = 0; bx < nbx_; ++bx) {
          if (!mark_[(std::size_t(bz) * nby_ + by) * nbx_ + bx]) continue;
          const int y0 = std::max(8 * int(by) - e_.lo[1], 0), y1 = std::min(8 * int(by) + 7 + e_.hi[1], ny_ - 1);
          std::fill(rows_of_bx_.begin() + std::ptrdiff_t(bx * std::size_t(ny_) + std::size_t(y0)),
                    rows_of_bx_.begin() + std::ptrdiff_t(bx * std::size_t(ny_) + std::size_t(y1) + 1), std::uint8_t(1));
        }
  }

  /// Of the slice last marked: ORs into out[0..ny) the rows quad column q meets; false if no
  /// candidate's extent reaches the column (out untouched).
  bool or_quad_rows(int q, std::uint8_t* out) const {
    const auto [bx0, bx1] = bricks_at(4 * q + 3, 0);  // quads are whole: any voxel of the quad
    const auto lo_b = bricks_at(4 * q, 0);
    // Locals: `out` is bytes and may alias any member, so a member in the loop would be
    // reloaded after every store (and the loop not vectorised).
    const int ny = ny_, nx = nx_, elo = e_.lo[0], ehi = e_.hi[0];
    const std::uint8_t* rows_of_bx = rows_of_bx_.data();
    bool any = false;
    for (int bx = std::min(bx0, lo_b.first); bx <= std::max(bx1, lo_b.second); ++bx) {
      const int q0 = std::max(8 * bx - elo, 0) / 4, q1 = std::min(8 * bx + 7 + ehi, nx - 1) / 4;
      if (q < q0 || q > q1) continue;
      const std::uint8_t* r = rows_of_bx + std::size_t(bx) * std::size_t(ny);
      for (int y = 0; y < ny; ++y) out[y] |= r[y];
      any = true;
    }
    return any;
  }

 private:
  std::pair<int, int> bricks_at(int i, int a) const {  // brick layers whose extent covers index i along axis a
    const int b0 = std::max(floor_div(i - e_.hi[std::size_t(a)], 8), 0);
    const int b1 = std::min(floor_div(i + e_.lo[std::size_t(a)], 8), nb_[std::size_t(a)] - 1);
    return {b0, b1};
  }
  const Extent& e_;
  const std::array<int, 3> nb_;
  const int nx_, ny_;
  const std::size_t nbx_, nby_;
  std::vector<std::uint8_t> mark_, rows_of_bx_, layer_;
  int q_lo_ = 0, q_hi_ = 0;
};

/// make_column_list without pairs: one unit per slice's column. Not inlined: inlined into
/// make_column_list, GCC 12 compiles its loops to half the speed (chest at -500: 1.6 ms
/// against 0.75 ms, measured).
[[gnu::noinline]] WorkList single_columns(const core::Grid& grid, const std::vector<std::uint32_t>& candidates,
                                          const Extent& e, const std::string& what) {
  CandidateRows cover(grid, candidates, e, what, 1);
  const int ny = grid.dims[1], nz = grid.dims[2], qx = cover.quad_columns();
  constexpr int kColumn = int(ISOTOUCH_LIST_PACK) - 1;  // outputs per unit at most
  WorkList w;
  w.z_first.assign(std::size_t(nz) + 1, 0);
  std::vector<std::uint8_t> rows(std::size_t(ny), 0);
  for (int z = 0; z < nz; ++z) {
    if (!cover.reaches(z)) {
      w.z_first[std::size_t(z) + 1] = std::uint32_t(w.unit_count());
      continue;
    }
    cover.mark_slice(z);
    for (int q = cover.q_lo(); q < cover.q_hi(); ++q) {
      std::fill(rows.begin(), rows.end(), std::uint8_t(0));
      if (!cover.or_quad_rows(q, rows.data())) continue;
      for (int y = 0; y < ny;) {
        if (!rows[std::size_t(y)]) {
          ++y;
          continue;
        }
        int end = y;
        while (end < ny && rows[std::size_t(end)] && end - y < kColumn) ++end;
        w.units.push_back(float(q + qx * z));
        w.units.push_back(float(y * int(ISOTOUCH_LIST_PACK) + (end - y)));
        w.quads += std::uint64_t(end - y);
        y = end;
      }
    }
    w.z_first[std::size_t(z) + 1] = std::uint32_t(w.unit_count());
  }
  return w;
}
}  // namespace

bool fused_pairs(const Plan& plan) { return plan.ops.size() == 3 && plan.ops[2].radius >= 1; }

namespace {
/// Appends to `w` the units of slice z over the rows `m` marks (m[q * ny + y] 1 where quad q
/// of row y needs an output): runs of at most ISOTOUCH_LIST_PACK - 1 rows per quad column;
/// pair: the unit also computes slice z + 1 (gauss_fused_list.comp).
void emit_runs(const std::uint8_t* m, int qx, int q0, int q1, int ny, int z, bool pair, WorkList& w) {
  constexpr int kColumn = int(ISOTOUCH_LIST_PACK) - 1;  // outputs per unit (per slice) at most
  for (int q = q0; q < q1; ++q) {
    const std::uint8_t* r = m + std::size_t(q) * std::size_t(ny);
    for (int y = 0; y < ny;) {
      // The next marked row and the end of its run (memchr: the library's vector scan).
      const void* first = std::memchr(r + y, 1, std::size_t(ny - y));
      if (!first) break;
      y = int(static_cast<const std::uint8_t*>(first) - r);
      const int span = std::min(ny - y, kColumn);
      const void* gap = std::memchr(r + y, 0, std::size_t(span));
      const int end = gap ? int(static_cast<const std::uint8_t*>(gap) - r) : y + span;
      w.units.push_back(float(2 * (q + qx * z) + (pair ? 1 : 0)));
      w.units.push_back(float(y * int(ISOTOUCH_LIST_PACK) + (end - y)));
      w.quads += std::uint64_t(end - y) * (pair ? 2u : 1u);
      y = end;
    }
  }
}

/// make_column_list's paired units of slices [z0, z1) (z0 even) into `w`, its z_first
/// entry z - z0 + 1 counting the units of `w` up to slice z. Not inlined (see single_columns).
[[gnu::noinline]] void paired_columns(const core::Grid& grid, const std::vector<std::uint32_t>& candidates,
                                      const Extent& e, const std::string& what, int z0, int z1, WorkList& w) {
  CandidateRows cover(grid, candidates, e, what, 2);
  const int ny = grid.dims[1], nz = grid.dims[2], qx = cover.quad_columns();
  const std::size_t cells = std::size_t(qx) * std::size_t(ny);
  // rows[q * ny + y]: 1 where quad q of row y of the slice meets some candidate's extent.
  // Only quad columns [q0, q1) can hold a marked row: the loops stay there (same units).
  const int q0 = cover.q_lo(), q1 = cover.q_hi();
  const std::size_t c0 = std::size_t(q0) * std::size_t(ny), c1 = std::size_t(q1) * std::size_t(ny);
  auto slice_rows = [&](int z, std::vector<std::uint8_t>& rows) {
    std::fill(rows.begin() + std::ptrdiff_t(c0), rows.begin() + std::ptrdiff_t(c1), std::uint8_t(0));
    if (!cover.reaches(z)) return;
    cover.mark_slice(z);
    for (int q = q0; q < q1; ++q) (void)cover.or_quad_rows(q, rows.data() + std::size_t(q) * std::size_t(ny));
  };
  w.z_first.assign(std::size_t(z1 - z0) + 1, 0);
  std::vector<std::uint8_t> a(cells), b(cells), both(cells), only_a(cells), only_b(cells);
  // Slices two at a time: the rows both need as pairs (one column computes both outputs,
  // sharing the x and y passes of their common slices), the rest as single units.
  for (int z = z0; z < z1; z += 2) {
    if (!cover.reaches(z) && (z + 1 == nz || !cover.reaches(z + 1))) {  // no units
      w.z_first[std::size_t(z - z0) + 1] = std::uint32_t(w.unit_count());
      if (z + 1 < nz) w.z_first[std::size_t(z - z0) + 2] = std::uint32_t(w.unit_count());
      continue;
    }
    slice_rows(z, a);
    if (z + 1 == nz) {
      emit_runs(a.data(), qx, q0, q1, ny, z, false, w);
      w.z_first[std::size_t(z - z0) + 1] = std::uint32_t(w.unit_count());
      continue;
    }
    slice_rows(z + 1, b);
    for (std::size_t i = c0; i < c1; ++i) {  // entries are 0 or 1
      both[i] = a[i] & b[i];
      only_a[i] = a[i] & (b[i] ^ 1u);
      only_b[i] = b[i] & (a[i] ^ 1u);
    }
    emit_runs(both.data(), qx, q0, q1, ny, z, true, w);
    emit_runs(only_a.data(), qx, q0, q1, ny, z, false, w);
    w.z_first[std::size_t(z - z0) + 1] = std::uint32_t(w.unit_count());
    emit_runs(only_b.data(), qx, q0, q1, ny, z + 1, false, w);
    w.z_first[std::size_t(z - z0) + 2] = std::uint32_t(w.unit_count());
  }
}
}  // namespace

namespace {
/// make_column_list's units in the order they are built (by z, then q, then y).
WorkList columns_in_build_order(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                                const std::string& what, bool pairs, unsigned threads) {
  if (!pairs) return single_columns(grid, candidates, e, what);
  // Slice pairs in contiguous parts, one list each, then joined in order: the same units
  // for any thread count.
  const int nz = grid.dims[2], n_pairs = (nz + 1) / 2;
  const unsigned parts = std::clamp(threads, 1u, unsigned(std::max(n_pairs, 1)));
  std::vector<WorkList> part(parts);
  auto first_slice = [&](std::size_t p) { return std::min(2 * int(p * std::size_t(n_pairs) / parts), nz); };
  parallel_for(parts, parts, 1, [&](std::size_t p0, std::size_t p1) {
    for (std::size_t p = p0; p < p1; ++p)
      paired_columns(grid, candidates, e, what, first_slice(p), first_slice(p + 1), part[p]);
  });
  WorkList w;
  w.z_first.assign(std::size_t(nz) + 1, 0);
  for (std::size_t p = 0; p < parts; ++p) {
    const std::uint32_t base = std::uint32_t(w.unit_count());
    const int z0 = first_slice(p), z1 = first_slice(p + 1);
    for (int z = z0; z < z1; ++z) w.z_first[std::size_t(z) + 1] = base + part[p].z_first[std::size_t(z - z0) + 1];
    w.units.insert(w.units.end(), part[p].units.begin(), part[p].units.end());
    w.quads += part[p].quads;
  }
  return w;
}

/// Orders each slice's units by their rows, longest first (stable: ties keep their order):
/// llvmpipe runs 8 invocations as one SIMD loop as long as its longest column, so
/// neighbouring units of like length waste fewer lanes (lanes doing work: chest at -500 HU
/// 0.92 -> 0.99, head CT 0.85 -> 0.92). z_first stays valid.
void longest_first(WorkList& w) {
  // A counting sort per slice (rows 1 .. ISOTOUCH_LIST_PACK - 1): stable, linear.
  constexpr int kPack = int(ISOTOUCH_LIST_PACK);
  std::vector<float> sorted(w.units.size());
  for (std::size_t z = 0; z + 1 < w.z_first.size(); ++z) {
    const std::size_t u0 = w.z_first[z], u1 = w.z_first[z + 1];
    std::array<std::size_t, kPack + 1> first{};  // first[kPack - n]: where units of n rows start
    for (std::size_t u = u0; u < u1; ++u) ++first[std::size_t(kPack - int(w.units[2 * u + 1]) % kPack) + 1];
    first[0] = u0;
    for (int k = 1; k <= kPack; ++k) first[std::size_t(k)] += first[std::size_t(k) - 1];
    for (std::size_t u = u0; u < u1; ++u) {
      const std::size_t to = first[std::size_t(kPack - int(w.units[2 * u + 1]) % kPack)]++;
      sorted[2 * to] = w.units[2 * u];
      sorted[2 * to + 1] = w.units[2 * u + 1];
    }
  }
  w.units.swap(sorted);
}
}  // namespace

WorkList make_column_list(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                          const std::string& what, bool pairs, unsigned threads) {
  WorkList w = columns_in_build_order(grid, candidates, e, what, pairs, threads);
  longest_first(w);
  return w;
}

}  // namespace isotouch::engine::sparse
