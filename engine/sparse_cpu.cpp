// sparse_cpu.cpp - the sparse chain's selection, publication and its one-thread CPU
// reference (engine/sparse_chain.h). Compiled with -ffp-contract=off (engine/CMakeLists.txt):
// the per-brick computation does the float operations of shaders/sparse_brick.comp, which
// are those of the dense passes (cpu_filters.cpp, cpu_gradient.cpp), in the same order.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <stdexcept>
#include <utility>

#ifdef __linux__
#include <sys/mman.h>
#endif
#if defined(__SSE2__)
#include <emmintrin.h>
#include <xmmintrin.h>
#endif

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/pool_recycler.h"
#include "isotouch/engine/sparse_chain.h"

namespace isotouch::engine {
namespace sparse {

namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr double kU = 0x1p-24;  // unit roundoff of float

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// make_bricked_field(BrickedInput, SampleFormat) when core provides it (found by ADL at
// instantiation); otherwise the field stays empty and the caller keeps the input.
template <class In>
auto make_field(In&& in, core::SampleFormat f, int) -> decltype(make_bricked_field(std::forward<In>(in), f)) {
  return make_bricked_field(std::forward<In>(in), f);
}
template <class In>
core::SampleField make_field(In&&, core::SampleFormat, long) {
  return {};
}
template <class In>
constexpr bool can_make_field(int) requires requires(In in) { make_bricked_field(std::move(in), core::SampleFormat::kFp32); } {
  return true;
}
template <class In>
constexpr bool can_make_field(long) {
  return false;
}
}  // namespace

std::string validate(const std::vector<PassDesc>& p) {
  if (std::string e = validate_passes(p); !e.empty()) return e;
  bool gradient = false;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const std::string at = "pass " + std::to_string(i) + " (" + pass_name(p[i].kind) + "): ";
    switch (p[i].kind) {
      case PassKind::Gaussian:
      case PassKind::Closing:
        if (gradient) return at + "filters must come before the gradient in the sparse chain";
        break;
      case PassKind::Gradient: gradient = true; break;
      case PassKind::BrickMinMax:
        if (p[i].halo != 1)
          return at + "the sparse chain selects bricks with halo 1 (the gradient's stencil), got halo " +
                 std::to_string(p[i].halo);
        break;
    }
  }
  if (!gradient) return "the sparse chain needs a gradient pass (a snapshot carries gradients)";
  return {};
}

Plan make_plan(const core::Grid& grid, const std::vector<PassDesc>& passes, const std::string& what) {
  Plan plan;
  double factor = 1.0;
  try {
    for (const PassDesc& p : passes) {
      if (p.kind == PassKind::Gaussian) {
        const GaussianAxes g = gaussian_axes(grid, p.sigma_mm);
        for (int a = 0; a < 3; ++a) {
          const auto& k = g.kernel[std::size_t(a)];
          const int r = int(k.size() / 2);
          plan.ops.push_back({a, r, OpKind::kGauss, std::uint32_t(plan.weights.size())});
          plan.weights.insert(plan.weights.end(), k.begin(), k.end());
          plan.radius[std::size_t(a)] += r;
          // See select(): one op moves the bound by at most (n + 3) u max|x|, n = 2r + 1 taps.
          factor *= 1.0 + double(2 * r + 1 + 3) * kU;
          plan.text += std::string(plan.text.empty() ? "" : ", ") + "gauss " + "xyz"[a] + " r=" + std::to_string(r);
        }
      } else if (p.kind == PassKind::Closing) {
        const auto r = closing_radii(grid, p.radius_mm);
        for (int k = 0; k < 6; ++k) {
          const int a = k % 3;
          plan.ops.push_back({a, r[std::size_t(a)], k < 3 ? OpKind::kMax : OpKind::kMin, 0});
          plan.radius[std::size_t(a)] += r[std::size_t(a)];
          plan.text += std::string(plan.text.empty() ? "" : ", ") + (k < 3 ? "max " : "min ") + "xyz"[a] +
                       " r=" + std::to_string(r[std::size_t(a)]);
        }
        plan.closing = true;
      }
    }
  } catch (const std::invalid_argument& e) {
    throw VolumeError(what + ": " + e.what());
  }
  for (int a = 0; a < 3; ++a) {
    plan.region[std::size_t(a)] = 11 + 2 * plan.radius[std::size_t(a)];
    plan.reach[std::size_t(a)] = plan.radius[std::size_t(a)] / 8 + 1;
  }
  // The factor's own rounding in double and the 1 + x products: far below this margin.
  plan.rel_eps = factor > 1.0 ? (factor - 1.0) * (1.0 + 1e-6) : 0.0;
  if (plan.text.empty()) plan.text = "no filter";
  return plan;
}

void RawRanges::init(const core::Grid& g) {
  bricks = core::brick_counts(g);
  const std::size_t n = std::size_t(bricks[0]) * std::size_t(bricks[1]) * std::size_t(bricks[2]);
  lo.assign(n, kInf);
  hi.assign(n, -kInf);
  nan.assign(n, 0);
}

void RawRanges::add_slice(const core::Grid& g, int z, const float* f) {
  const int nx = g.dims[0], ny = g.dims[1];
  const std::size_t layer = std::size_t(z / 8) * std::size_t(bricks[0]) * std::size_t(bricks[1]);
  for (int y = 0; y < ny; ++y) {
    const float* row = f + std::size_t(y) * std::size_t(nx);
    const std::size_t b0 = layer + std::size_t(y / 8) * std::size_t(bricks[0]);
    for (int bx = 0; bx < bricks[0]; ++bx) {
      const int x0 = bx * 8, x1 = std::min(x0 + 8, nx);
      float mn = lo[b0 + std::size_t(bx)], mx = hi[b0 + std::size_t(bx)];
      bool n = false;
      for (int x = x0; x < x1; ++x) {
        const float v = row[x];
        n |= v != v;
        mn = v < mn ? v : mn;
        mx = v > mx ? v : mx;
      }
      lo[b0 + std::size_t(bx)] = mn;
      hi[b0 + std::size_t(bx)] = mx;
      if (n) nan[b0 + std::size_t(bx)] = 1;
    }
  }
}

void RawRanges::set_brick(const core::Grid& g, const float* voxels, std::uint32_t id) {
  const auto b = core::brick_coords(id, bricks);
  const int nx = g.dims[0], ny = g.dims[1];
  const int x0 = b[0] * 8, x1 = std::min(x0 + 8, nx), y0 = b[1] * 8, y1 = std::min(y0 + 8, ny), z0 = b[2] * 8,
            z1 = std::min(z0 + 8, g.dims[2]);
  float mn = kInf, mx = -kInf;
  bool n = false;
  for (int z = z0; z < z1; ++z)  // add_slice's order: slices, rows, x ascending
    for (int y = y0; y < y1; ++y) {
      const float* row = voxels + (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(nx);
      for (int x = x0; x < x1; ++x) {
        const float v = row[x];
        n |= v != v;
        mn = v < mn ? v : mn;
        mx = v > mx ? v : mx;
      }
    }
  lo[id] = mn;
  hi[id] = mx;
  nan[id] = n ? 1 : 0;
}

namespace {
/// The tail of select() for one brick: widens [lo, hi] (the min / max over the reach) by
/// the Gaussians' rounding bound, outward, and says whether the brick is a candidate.
bool widen_and_decide(float& lo, float& hi, bool nan, const Plan& plan, const core::Isosurface& iso) {
  if (lo <= hi && plan.rel_eps > 0) {
    const double abs_eps = double(plan.ops.size() * 130) * 0x1p-149;
    const double A = std::max(std::fabs(double(lo)), std::fabs(double(hi)));
    const double d = A * plan.rel_eps + abs_eps;
    const double l = double(lo) - d, h = double(hi) + d;
    lo = float(l);  // rounded outward
    if (double(lo) > l) lo = std::nextafter(lo, -kInf);
    hi = float(h);
    if (double(hi) < h) hi = std::nextafter(hi, kInf);
  }
  float tile = 0;
  const bool uniform = core::tile_value(lo, hi, iso, 0.0f, tile);
  const bool nan_matters = nan && (plan.closing || (lo <= hi && iso.contains(tile)));
  return !uniform || nan_matters;
}
}  // namespace

// Why the widened range is a bound of the smoothed field over the brick + 1 voxel:
// - a box max / min (closing) returns one of its finite inputs (NaN skipped), so its output
//   lies in the range of the inputs over its window; an all-NaN window gives -Inf / +Inf,
//   which is why a NaN in the neighbourhood makes a brick a candidate when a closing runs;
// - a Gaussian op with n = 2r + 1 taps has float weights w_k >= 0, each the double
//   e_k / sum e rounded once, so sum w_k <= 1 + u (u = 2^-24); the products and the
//   running sum are rounded n times, |fl(sum) - sum w_k x_k| <= gamma_{n+1} sum w_k |x_k|
//   (Higham, Accuracy and Stability, eq. 3.4), gamma_{n+1} = (n+1) u / (1 - (n+1) u).
//   With A = max |x| over the window: the output lies in [lo - (n + 3) u A, hi + (n + 3) u A]
//   (u A from the weight sum, (n + 1) u (1 + u) A / (1 - (n+1) u) < (n + 2) u A from the
//   rounding for n < 2^10) and A grows by the factor 1 + (n + 3) u. Over all ops the bound
//   moves by A (prod(1 + (n_i + 3) u) - 1) = A rel_eps. Gradual underflow adds at most
//   2^-149 per rounding: the absolute term below.
// - NaN outputs (a NaN or +Inf and -Inf in a Gaussian window) are skipped by the range.
// The window: the smoothed voxels [8b - 1, 8b + 8] read raw voxels [8b - 1 - R, 8b + 8 + R]
// (clamped to the grid: a clamped tap reads a border voxel of the same window), exactly
// these and no more - not the whole neighbouring bricks (on the chest at -500 HU, 4082
// candidates instead of 5310 for 3303 active).
// Min / max over a set do not depend on the order of the folds (NaN skipped, -0 made +0 at
// the end): select() and select_brick() agree bit for bit.
namespace {
struct Fold {
  float lo = kInf, hi = -kInf;
  bool nan = false;
  void add(float v) {
    nan = nan || v != v;
    lo = v < lo ? v : lo;
    hi = v > hi ? v : hi;
  }
};
/// Fold over rows 4 values at a time; a row's last 4 overlap the ones before (min, max and
/// the NaN flag do not depend on the order or on seeing a value twice; -0 / +0 are for the
/// caller to make +0). GCC / Clang vector extensions.
struct RowFold {
  typedef float v4 __attribute__((vector_size(16)));
  v4 lo = {kInf, kInf, kInf, kInf}, hi = -lo, nn = {0.0f, 0.0f, 0.0f, 0.0f};
  Fold tail;  ///< rows shorter than 4
  void row(const float* r, int w) {
    if (w < 4) {
      for (int x = 0; x < w; ++x) tail.add(r[x]);
      return;
    }
    const v4 one = {1.0f, 1.0f, 1.0f, 1.0f};
    for (int o = 0;; o = std::min(o + 4, w - 4)) {
      v4 v;
      std::memcpy(&v, r + o, sizeof v);
      lo = v < lo ? v : lo;
      hi = v > hi ? v : hi;
      nn = v != v ? one : nn;
      if (o == w - 4) break;
    }
  }
  Fold result() const {
    Fold f = tail;
    for (int i = 0; i < 4; ++i) {
      f.lo = lo[i] < f.lo ? lo[i] : f.lo;
      f.hi = hi[i] > f.hi ? hi[i] : f.hi;
      f.nan = f.nan || nn[i] != 0.0f;
    }
    return f;
  }
};
/// Element-wise fold over slices za .. zb of one row (`row0` the row in slice 0, slices
/// `slice` floats apart), elements 0 .. sx - 1: lo / hi the min / max of the non-NaN values
/// (+-Inf where all are NaN), nn 1 where a NaN was seen, else 0. 16 elements at a time with
/// the slices innermost (accumulators in registers, each voxel loaded once, nothing stored
/// per slice); GCC / Clang vector extensions: vector min / max on any target.
void fold_rows_z(const float* row0, std::size_t slice, int za, int zb, std::size_t sx, float* lo, float* hi,
                 float* nn) {
  typedef float v4 __attribute__((vector_size(16)));
  typedef std::int32_t v4i __attribute__((vector_size(16)));
  constexpr int kV = 4;  // vectors per step: 16 elements
  const v4 inf = {kInf, kInf, kInf, kInf};
  const v4i one_bits = {0x3f800000, 0x3f800000, 0x3f800000, 0x3f800000};  // 1.0f
  std::size_t x = 0;
  for (; x + 4 * kV <= sx; x += 4 * kV) {
    v4 l[kV], h[kV];
    v4i n[kV];
    for (int j = 0; j < kV; ++j) {
      l[j] = inf;
      h[j] = -inf;
      n[j] = one_bits - one_bits;
    }
    for (int z = za; z <= zb; ++z) {
      const float* p = row0 + std::size_t(z) * slice + x;
      for (int j = 0; j < kV; ++j) {
        v4 v;
        std::memcpy(&v, p + 4 * j, sizeof v);
        l[j] = v < l[j] ? v : l[j];
        h[j] = v > h[j] ? v : h[j];
        n[j] |= v != v;
      }
    }
    for (int j = 0; j < kV; ++j) {
      const v4i nf = n[j] & one_bits;  // 1.0f or 0.0f
      std::memcpy(lo + x + 4 * j, &l[j], sizeof(v4));
      std::memcpy(hi + x + 4 * j, &h[j], sizeof(v4));
      std::memcpy(nn + x + 4 * j, &nf, sizeof(v4i));
    }
  }
  for (; x < sx; ++x) {
    Fold f;
    for (int z = za; z <= zb; ++z) f.add(row0[std::size_t(z) * slice + x]);
    lo[x] = f.lo;
    hi[x] = f.hi;
    nn[x] = f.nan ? 1.0f : 0.0f;
  }
}

}  // namespace

Selection select(const core::Grid& grid, const float* voxels, const Plan& plan, const core::Isosurface& iso,
                 unsigned threads, float* copy_to) {
  const auto nb = core::brick_counts(grid);
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const std::size_t sx = std::size_t(nx), slice = sx * std::size_t(ny);
  const std::size_t nbx = std::size_t(nb[0]), nby = std::size_t(nb[1]), layer = nbx * nby;
  const std::size_t total = layer * std::size_t(nb[2]);
  Selection s;
  s.lo.resize(total);
  s.hi.resize(total);
  s.nan.resize(total);
  std::vector<std::uint8_t> cand(total, 0);
  // Per brick layer, row by row: the row's fold over the layer's z-window (fold_rows_z:
  // element by element, the slices innermost in registers), folded into the y-fold of every
  // brick row whose window holds the row; then per brick over its x-window. Each voxel is
  // read from memory once per layer window that holds it, and copied (copy_to) by the
  // thread whose layer holds its slice. Element-wise selects (a NaN voxel
  // never enters lo / hi, it sets its own flag) that the compiler turns into vector min / max.
  threads = threads_for(grid.voxel_count(), threads);
  parallel_for(std::size_t(nb[2]), threads, 1, [&](std::size_t bz0, std::size_t bz1) {
    std::vector<float> rlo(sx), rhi(sx), rnan(sx), ylo(nby * sx), yhi(nby * sx), ynan(nby * sx);
    for (std::size_t bz = bz0; bz < bz1; ++bz) {
      std::fill(ylo.begin(), ylo.end(), kInf);
      std::fill(yhi.begin(), yhi.end(), -kInf);
      std::fill(ynan.begin(), ynan.end(), 0.0f);
      const auto [za, zb] = brick_window(int(bz), plan.radius[2], nz);
      // The layer's own slices copied whole (sequential writes; its rows are then in cache
      // for the folds below).
      const std::size_t own0 = 8 * bz, own1 = std::min<std::size_t>(8 * bz + 8, std::size_t(nz));
      if (copy_to) std::memcpy(copy_to + own0 * slice, voxels + own0 * slice, (own1 - own0) * slice * sizeof(float));
      for (int y = 0; y < ny; ++y) {
        float *lo = rlo.data(), *hi = rhi.data(), *nn = rnan.data();
        fold_rows_z(voxels + std::size_t(y) * sx, slice, za, zb, sx, lo, hi, nn);
        // Brick rows by whose window [8 by - 1 - R, 8 by + 8 + R] holds y.
        const int by0 = std::max(0, (y - 8 - plan.radius[1] + 7) / 8);
        const int by1 = std::min(nb[1] - 1, (y + 1 + plan.radius[1]) / 8);
        for (int by = by0; by <= by1; ++by) {
          float *yl = ylo.data() + std::size_t(by) * sx, *yh = yhi.data() + std::size_t(by) * sx,
                *yn = ynan.data() + std::size_t(by) * sx;
          for (std::size_t x = 0; x < sx; ++x) {
            yl[x] = lo[x] < yl[x] ? lo[x] : yl[x];
            yh[x] = hi[x] > yh[x] ? hi[x] : yh[x];
            yn[x] = nn[x] > yn[x] ? nn[x] : yn[x];
          }
        }
      }
      for (int by = 0; by < nb[1]; ++by) {
        const float *yl = ylo.data() + std::size_t(by) * sx, *yh = yhi.data() + std::size_t(by) * sx,
                    *yn = ynan.data() + std::size_t(by) * sx;
        for (int bx = 0; bx < nb[0]; ++bx) {
          const auto [xa, xb] = brick_window(bx, plan.radius[0], nx);
          Fold f;
          for (int x = xa; x <= xb; ++x) {
            f.lo = yl[x] < f.lo ? yl[x] : f.lo;
            f.hi = yh[x] > f.hi ? yh[x] : f.hi;
            f.nan = f.nan || yn[x] != 0.0f;
          }
          const std::size_t id = bz * layer + std::size_t(by) * nbx + std::size_t(bx);
          s.lo[id] = f.lo + 0.0f;  // -0 -> +0
          s.hi[id] = f.hi + 0.0f;
          s.nan[id] = f.nan ? 1 : 0;
          cand[id] = widen_and_decide(s.lo[id], s.hi[id], f.nan, plan, iso) ? 1 : 0;
        }
      }
    }
  });
  for (std::size_t id = 0; id < total; ++id)
    if (cand[id]) s.candidates.push_back(std::uint32_t(id));
  return s;
}

namespace {
/// The range of the box [x0, x0 + 10) x [ya, yb] x [za, zb] of `f`: three 4-lane folds per
/// row (lanes x0 .. x0 + 3, + 4 .. + 7, + 6 .. + 9: lanes read twice change no min or max),
/// then over the lanes. GCC / Clang vector extensions: vector min / max on any target.
CandidateRange box_range10(const float* f, std::size_t sx, std::size_t slice, int x0, int ya, int yb, int za,
                           int zb) {
  typedef float v4 __attribute__((vector_size(16)));
  const v4 one = {1.0f, 1.0f, 1.0f, 1.0f};
  v4 lo = {kInf, kInf, kInf, kInf}, hi = -lo, nn = one - one;
  for (int z = za; z <= zb; ++z)
    for (int y = ya; y <= yb; ++y) {
      const float* row = f + std::size_t(z) * slice + std::size_t(y) * sx + std::size_t(x0);
      for (const int o : {0, 4, 6}) {
        v4 v;
        std::memcpy(&v, row + o, sizeof v);
        lo = v < lo ? v : lo;
        hi = v > hi ? v : hi;
        nn = v != v ? one : nn;
      }
    }
  Fold r;
  for (int i = 0; i < 4; ++i) {
    r.lo = lo[i] < r.lo ? lo[i] : r.lo;
    r.hi = hi[i] > r.hi ? hi[i] : r.hi;
    r.nan = r.nan || nn[i] != 0.0f;
  }
  return {r.lo, r.hi, r.nan};
}
}  // namespace

std::vector<CandidateRange> candidate_ranges(const core::Grid& grid, const float* f,
                                             const std::vector<std::uint32_t>& candidates, unsigned threads) {
  const auto nb = core::brick_counts(grid);
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const std::size_t sx = std::size_t(nx), slice = sx * std::size_t(ny);
  std::vector<CandidateRange> out(candidates.size());
  threads = threads_for(std::uint64_t(candidates.size()) * 1000u, threads);
  parallel_for(candidates.size(), threads, 64, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      const auto b = core::brick_coords(candidates[c], nb);
      const auto [xa, xb] = brick_window(b[0], 0, nx);
      const auto [ya, yb] = brick_window(b[1], 0, ny);
      const auto [za, zb] = brick_window(b[2], 0, nz);
      CandidateRange r{kInf, -kInf, false};
      if (xb - xa + 1 == 10) {
        r = box_range10(f, sx, slice, xa, ya, yb, za, zb);
      } else {  // a brick at the grid's edge along x: voxel by voxel
        Fold e;
        for (int z = za; z <= zb; ++z)
          for (int y = ya; y <= yb; ++y)
            for (int x = xa; x <= xb; ++x) e.add(f[std::size_t(z) * slice + std::size_t(y) * sx + std::size_t(x)]);
        r = {e.lo, e.hi, e.nan};
      }
      out[c] = {r.lo + 0.0f, r.hi + 0.0f, r.nan};  // -0 -> +0, as CandidateCpu::range
    }
  });
  return out;
}

BrickSelection select_brick(const core::Grid& grid, const float* voxels, const Plan& plan,
                            const core::Isosurface& iso, std::uint32_t id) {
  const auto b = core::brick_coords(id, core::brick_counts(grid));
  const int nx = grid.dims[0], ny = grid.dims[1];
  const auto [x0, x1] = brick_window(b[0], plan.radius[0], nx);
  const auto [y0, y1] = brick_window(b[1], plan.radius[1], ny);
  const auto [z0, z1] = brick_window(b[2], plan.radius[2], grid.dims[2]);
  // 4 voxels at a time (RowFold; -0 / +0 are made +0 below).
  RowFold rf;
  const int w = x1 - x0 + 1;
  for (int z = z0; z <= z1; ++z)
    for (int y = y0; y <= y1; ++y)
      rf.row(voxels + (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(nx) + x0, w);
  const Fold f = rf.result();
  BrickSelection out{f.lo + 0.0f, f.hi + 0.0f, f.nan, false};
  out.candidate = widen_and_decide(out.lo, out.hi, out.nan, plan, iso);
  return out;
}

std::uint64_t loop_trips_per_brick(const Plan& plan) {
  // Mirrors shaders/sparse_brick.comp loop by loop; a loop over `count` items with a
  // workgroup of 8 runs ceil(count / 8) trips, + 1 for the trip that leaves it. llvmpipe
  // runs both sides of every branch it cannot prove uniform (masked), and a loop on a
  // side no lane takes still costs one trip.
  constexpr std::uint64_t kWg = 8;  // ISOTOUCH_SPARSE_WG (sparse_chain.cpp pins it)
  auto strided = [](std::uint64_t count) { return (count + kWg - 1) / kWg + 1; };
  auto box = [](const std::array<int, 3>& w) {
    return std::uint64_t(std::max(w[0], 0)) * std::uint64_t(std::max(w[1], 0)) * std::uint64_t(std::max(w[2], 0));
  };
  std::uint64_t trips = 1;  // the workgroup's loop over its bricks
  trips += plan.ops.empty() ? strided(box(plan.region)) : 1;  // raw region copy
  trips += plan.ops.size() + 1;                                // loop over the ops
  std::array<int, 3> m{0, 0, 0};
  for (const Op& o : plan.ops) {
    m[std::size_t(o.axis)] += o.radius;
    std::array<int, 3> w{};
    for (std::size_t k = 0; k < 3; ++k) w[k] = plan.region[k] - 2 * m[k];
    const std::uint64_t items = (box(w) + kWg - 1) / kWg;
    // items, each a loop over the taps (+ 1 for the other kind's tap loop); + 3 for the
    // first-op / later-op branch not taken
    trips += items * (std::uint64_t(2 * o.radius + 1) + 1 + 1) + 1 + 3;
  }
  trips += strided(10 * 10 * 10);  // range of the brick + 1 voxel
  trips += 3 + 1;                  // reduction over the 8 lanes
  trips += strided(729);           // the 9^3 samples of an active brick
  trips += plan.ops.size() + 2 + 1;  // the budget check after each brick
  return trips;
}

std::uint64_t max_bricks_per_workgroup(const Plan& plan) {
  return std::max<std::uint64_t>(1, kLoopBudget / loop_trips_per_brick(plan));
}

float threshold(const core::Isosurface& iso) {
  float f = float(iso.tau);
  if (iso.inside == core::InsideIs::kAbove) {
    if (double(f) > iso.tau) f = std::nextafter(f, -kInf);
  } else {
    if (double(f) < iso.tau) f = std::nextafter(f, kInf);
  }
  return f;
}

bool is_active(const CandidateRange& r, const core::Isosurface& iso, float background, float& tile) {
  if (!core::tile_value(r.lo, r.hi, iso, background, tile)) return true;
  return r.nan && r.lo <= r.hi && iso.contains(tile);
}

namespace {
#if defined(__SSE2__)
/// Samples x0 + 0 .. 7 of one row whose x neighbours all lie inside the row (x0 >= 1,
/// x0 + 8 < nx): the scalar loop's float operations (a subtract, then a multiply, each
/// rounded; no contraction), 4 lanes at a time, transposed into Sample order. `ya`, `yb`,
/// `za`, `zb`: the rows the y and z differences read (null: flat, gradient 0).
void interior_samples8(const float* row, int x0, float kx, const float* ya, const float* yb, float ky, const float* za,
                       const float* zb, float kz, core::Sample* o, bool stream) {
  const __m128 vkx = _mm_set1_ps(kx), vky = _mm_set1_ps(ky), vkz = _mm_set1_ps(kz);
  for (int i = 0; i < 8; i += 4) {
    const int x = x0 + i;
    __m128 v = _mm_loadu_ps(row + x);
    __m128 gx = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(row + x + 1), _mm_loadu_ps(row + x - 1)), vkx);
    __m128 gy = ya ? _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(ya + x), _mm_loadu_ps(yb + x)), vky) : _mm_setzero_ps();
    __m128 gz = za ? _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(za + x), _mm_loadu_ps(zb + x)), vkz) : _mm_setzero_ps();
    _MM_TRANSPOSE4_PS(v, gx, gy, gz);  // rows become samples x, x + 1, x + 2, x + 3
    float* d = &o[i].value;
    if (stream) {
      _mm_stream_ps(d, v);
      _mm_stream_ps(d + 4, gx);
      _mm_stream_ps(d + 8, gy);
      _mm_stream_ps(d + 12, gz);
    } else {
      _mm_storeu_ps(d, v);
      _mm_storeu_ps(d + 4, gx);
      _mm_storeu_ps(d + 8, gy);
      _mm_storeu_ps(d + 12, gz);
    }
  }
}
#endif

/// Writes one sample; `stream` (16-byte aligned `d`, SSE2): a non-temporal store, which
/// writes the line without reading it first (a recycled pool's lines are not in cache).
inline void put_sample(core::Sample* d, const core::Sample& v, bool stream) {
#if defined(__SSE2__)
  if (stream) {
    _mm_stream_ps(&d->value, _mm_set_ps(v.gz, v.gy, v.gx, v.value));
    return;
  }
#endif
  (void)stream;
  *d = v;
}
}  // namespace

void brick_samples(const core::Grid& grid, const float* f, const std::array<int, 3>& b, float background,
                   core::Sample* out) {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const GradientConstants k = gradient_constants(grid);
  const std::size_t sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
  const int x0 = 8 * b[0], in_x = std::min(9, nx - x0);
  const core::Sample outside{background, 0.0f, 0.0f, 0.0f};
  // Every one of the 729 samples is written in order, 16 B each: where `out` is 16-byte
  // aligned (a pool's slot) the stores stream past the cache (the same bits).
#if defined(__SSE2__)
  const bool stream = reinterpret_cast<std::uintptr_t>(out) % 16 == 0;
#else
  const bool stream = false;
#endif
  // One axis' rule for a whole row, as compute_samples_cpu: (a[x] - b[x]) * k, 0 when flat.
  struct Rule {
    const float* a;
    const float* b;
    float k;
    bool flat;
  };
  auto rule = [](int i, int n, const float* row, std::size_t stride, float inv_2h, float inv_h) {
    if (n < 2) return Rule{row, row, 0.0f, true};
    if (i == 0) return Rule{row + stride, row, inv_h, false};
    if (i == n - 1) return Rule{row, row - stride, inv_h, false};
    return Rule{row + stride, row - stride, inv_2h, false};
  };
  for (int kk = 0; kk < 9; ++kk)
    for (int j = 0; j < 9; ++j) {
      core::Sample* o = out + 9 * j + 81 * kk;
      const int y = 8 * b[1] + j, z = 8 * b[2] + kk;
      int i = 0;
      if (y < ny && z < nz) {
        const float* row = f + std::size_t(z) * sz + std::size_t(y) * sy;
        const Rule dy = rule(y, ny, row, sy, k.inv_2h[1], k.inv_h[1]);
        const Rule dz = rule(z, nz, row, sz, k.inv_2h[2], k.inv_h[2]);
#if defined(__SSE2__)
        if (x0 >= 1 && x0 + 9 < nx) {  // samples 0 .. 7 and their x neighbours inside the row
          interior_samples8(row, x0, k.inv_2h[0], dy.flat ? nullptr : dy.a, dy.b, dy.k, dz.flat ? nullptr : dz.a, dz.b,
                            dz.k, o, stream);
          i = 8;
        }
#endif
        for (; i < in_x; ++i) {
          const int x = x0 + i;
          float gx = 0.0f;
          if (nx >= 2)
            gx = x == 0        ? (row[1] - row[0]) * k.inv_h[0]
                 : x == nx - 1 ? (row[nx - 1] - row[nx - 2]) * k.inv_h[0]
                               : (row[x + 1] - row[x - 1]) * k.inv_2h[0];
          const float gy = dy.flat ? 0.0f : (dy.a[x] - dy.b[x]) * dy.k;
          const float gz = dz.flat ? 0.0f : (dz.a[x] - dz.b[x]) * dz.k;
          put_sample(o + i, {row[x], gx, gy, gz}, stream);
        }
      }
      for (; i < 9; ++i) put_sample(o + i, outside, stream);
    }
#if defined(__SSE2__)
  if (stream) _mm_sfence();  // the streamed stores ordered before whatever publishes the pool
#endif
}

void publish(const core::Grid& grid, const Selection& sel, const std::vector<CandidateRange>& ranges,
             const std::function<const core::Sample*(std::size_t)>& samples, const core::Isosurface& iso,
             float background, core::SampleFormat format, bool keep_input, SparseOutput& out,
             const std::shared_ptr<PoolRecycler>& recycler) {
  publish_fill(
      grid, sel, ranges,
      [&](std::size_t c, core::Sample* dst) {
        const core::Sample* s = samples(c);
        std::copy(s, s + core::kBrickSamples, dst);
      },
      1, iso, background, format, keep_input, out, recycler);
}

void publish_fill(const core::Grid& grid, const Selection& sel, const std::vector<CandidateRange>& ranges,
                  const std::function<void(std::size_t, core::Sample*)>& fill, unsigned threads,
                  const core::Isosurface& iso, float background, core::SampleFormat format, bool keep_input,
                  SparseOutput& out, const std::shared_ptr<PoolRecycler>& recycler) {
  core::BrickedInput in;
  in.grid = grid;
  in.background = background;
  const std::size_t total = sel.lo.size();
  in.tile.assign(total, 0.0f);
  std::vector<std::uint8_t> is_cand(total, 0);
  for (std::uint32_t id : sel.candidates) is_cand[id] = 1;
  for (std::size_t id = 0; id < total; ++id) {
    if (is_cand[id]) continue;
    if (!core::tile_value(sel.lo[id], sel.hi[id], iso, background, in.tile[id]))
      throw std::logic_error("sparse publish: brick " + std::to_string(id) + " straddles but is no candidate");
  }
  std::vector<std::uint8_t> active(sel.candidates.size(), 0);
  std::size_t n_active = 0;
  for (std::size_t c = 0; c < sel.candidates.size(); ++c) {
    float tile = 0;
    active[c] = is_active(ranges[c], iso, background, tile);
    if (active[c])
      ++n_active;
    else
      in.tile[sel.candidates[c]] = tile;
  }
  in.active.reserve(n_active);
  std::vector<std::size_t> cand_of_slot;
  cand_of_slot.reserve(n_active);
  for (std::size_t c = 0; c < sel.candidates.size(); ++c)
    if (active[c]) {
      in.active.push_back(sel.candidates[c]);
      cand_of_slot.push_back(c);
    }
  // Sized without a write (core::SamplePool): `fill` writes every sample of every slot, so
  // a fresh pool's pages are first touched by the filling threads, not zeroed on this one
  // first; a recycled one's are resident already.
  const std::size_t n_samples = n_active * std::size_t(core::kBrickSamples);
  in.pool = recycler ? recycler->take(n_samples) : fresh_pool(n_samples);
  in.recycle = recycler;
  parallel_for(n_active, threads, 16, [&](std::size_t b, std::size_t e) {
    for (std::size_t slot = b; slot < e; ++slot) fill(cand_of_slot[slot], in.pool.data() + slot * core::kBrickSamples);
  });
  SparseStats& st = out.stats;
  st.bricks_total = total;
  st.candidates = sel.candidates.size();
  st.active = n_active;
  const std::uint64_t per_sample = format == core::SampleFormat::kFp32 ? 16 : 8;
  st.snapshot_bytes = 4 * std::uint64_t(total) + 16 * std::uint64_t(total - n_active) +
                      std::uint64_t(n_active) * core::kBrickSamples * per_sample +
                      (format == core::SampleFormat::kUnorm16 ? 32 * std::uint64_t(n_active) : 0);
  st.dense_fp32_bytes = std::uint64_t(grid.voxel_count()) * 16;
  if constexpr (can_make_field<core::BrickedInput>(0)) {
    if (keep_input) {
      out.field = make_field(core::BrickedInput(in), format, 0);
      out.input = std::move(in);
    } else {
      out.field = make_field(std::move(in), format, 0);
    }
  } else {
    out.input = std::move(in);  // no builder in core yet: the input is the result
  }
}

// ---------------------------------------------------------------- CPU reference

/// The region of one candidate brick and its computation, operation for operation as
/// shaders/sparse_brick.comp (the loops run in a different order; every output is one
/// independent expression, so the order of the outputs does not matter).
class BrickCpu {
 public:
  BrickCpu(const Volume& v, const Plan& p) : vol_(v), plan_(p) {
    for (int a = 0; a < 3; ++a) S_[a] = p.region[std::size_t(a)];
    buf_[0].resize(std::size_t(S_[0]) * std::size_t(S_[1]) * std::size_t(S_[2]));
    buf_[1].resize(buf_[0].size());
    k_ = gradient_constants(v.grid);
  }

  CandidateRange range(std::uint32_t id, const std::array<int, 3>& nb) {
    const auto b = core::brick_coords(id, nb);
    for (int a = 0; a < 3; ++a) {
      const int n = vol_.grid.dims[std::size_t(a)];
      g0_[a] = 8 * b[std::size_t(a)] - 1 - plan_.radius[std::size_t(a)];
      vlo_[a] = std::max(-g0_[a], 0);
      vhi_[a] = std::min(S_[a] - 1, n - 1 - g0_[a]);
    }
    const int nx = vol_.grid.dims[0], ny = vol_.grid.dims[1];
    const std::size_t row_bytes = std::size_t(vhi_[0] - vlo_[0] + 1) * sizeof(float);
    for (int z = vlo_[2]; z <= vhi_[2]; ++z)
      for (int y = vlo_[1]; y <= vhi_[1]; ++y)
        std::memcpy(&buf_[0][at(vlo_[0], y, z)],
                    &vol_.voxels[(std::size_t(g0_[2] + z) * std::size_t(ny) + std::size_t(g0_[1] + y)) * std::size_t(nx) +
                                 std::size_t(g0_[0] + vlo_[0])],
                    row_bytes);
    cur_ = 0;
    int m[3] = {0, 0, 0};
    for (const Op& op : plan_.ops) {
      int e[3] = {0, 0, 0};
      e[op.axis] = op.radius;
      int lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::max(m[a] + e[a], vlo_[a]);
        hi[a] = std::min(S_[a] - 1 - m[a] - e[a], vhi_[a]);
      }
      const int stride = op.axis == 0 ? 1 : (op.axis == 1 ? S_[0] : S_[0] * S_[1]);
      const int ilo = vlo_[op.axis], ihi = vhi_[op.axis], r = op.radius;
      const float* src = buf_[cur_].data();
      float* dst = buf_[1 - cur_].data();
      const float* w = plan_.weights.data() + op.w_offset;
      for (int z = lo[2]; z <= hi[2]; ++z)
        for (int y = lo[1]; y <= hi[1]; ++y)
          for (int x = lo[0]; x <= hi[0]; ++x) {
            const int l[3] = {x, y, z};
            const int i = l[op.axis];
            const int o = int(at(x, y, z));
            const int line = o - i * stride;
            if (op.kind == OpKind::kGauss) {
              float acc = 0.0f;
              for (int k = -r; k <= r; ++k) {
                const float v = src[line + std::clamp(i + k, ilo, ihi) * stride];
                const float term = w[k + r] * v;
                acc = acc + term;
              }
              dst[o] = acc;
            } else {
              const bool is_max = op.kind == OpKind::kMax;
              float mm = is_max ? -kInf : kInf;
              for (int k = -r; k <= r; ++k) {
                const float v = src[line + std::clamp(i + k, ilo, ihi) * stride];
                mm = is_max ? (v > mm ? v : mm) : (v < mm ? v : mm);
              }
              dst[o] = mm;
            }
          }
      for (int a = 0; a < 3; ++a) m[a] += e[a];
      cur_ = 1 - cur_;
    }
    const float* f = buf_[cur_].data();
    RowFold rf;  // 4 values at a time (-0 / +0 made +0 below)
    const int x0 = std::max(plan_.radius[0], vlo_[0]), w = std::min(plan_.radius[0] + 9, vhi_[0]) - x0 + 1;
    for (int z = std::max(plan_.radius[2], vlo_[2]); z <= std::min(plan_.radius[2] + 9, vhi_[2]); ++z)
      for (int y = std::max(plan_.radius[1], vlo_[1]); y <= std::min(plan_.radius[1] + 9, vhi_[1]); ++y)
        rf.row(f + at(x0, y, z), w);
    const Fold fo = rf.result();
    CandidateRange rg{fo.lo, fo.hi, fo.nan};
    rg.lo = rg.lo + 0.0f;  // -0 -> +0, as the shader (whose reduction order differs)
    rg.hi = rg.hi + 0.0f;
    return rg;
  }

  const core::Grid& grid() const { return vol_.grid; }

  /// The 9^3 samples of the brick of the last range() call.
  void samples(core::Sample* out, float background) const {
    const float* f = buf_[cur_].data();
    const auto& d = vol_.grid.dims;
    const int sx = S_[0], sxy = S_[0] * S_[1];
    if (interior_samples(f, out, sx, sxy)) return;
    for (int k = 0; k < 9; ++k)
      for (int j = 0; j < 9; ++j)
        for (int i = 0; i < 9; ++i) {
          const int g[3] = {g0_[0] + 1 + plan_.radius[0] + i, g0_[1] + 1 + plan_.radius[1] + j,
                            g0_[2] + 1 + plan_.radius[2] + k};
          core::Sample& s = out[i + 9 * j + 81 * k];
          if (g[0] >= d[0] || g[1] >= d[1] || g[2] >= d[2]) {
            s = {background, 0.0f, 0.0f, 0.0f};
            continue;
          }
          const int p = int(at(g[0] - g0_[0], g[1] - g0_[1], g[2] - g0_[2]));
          const float c = f[p];
          const float xl = g[0] > 0 ? f[p - 1] : c, xh = g[0] + 1 < d[0] ? f[p + 1] : c;
          const float yl = g[1] > 0 ? f[p - sx] : c, yh = g[1] + 1 < d[1] ? f[p + sx] : c;
          const float zl = g[2] > 0 ? f[p - sxy] : c, zh = g[2] + 1 < d[2] ? f[p + sxy] : c;
          s = {c, diff(g[0], d[0], xl, c, xh, k_.inv_2h[0], k_.inv_h[0]),
               diff(g[1], d[1], yl, c, yh, k_.inv_2h[1], k_.inv_h[1]),
               diff(g[2], d[2], zl, c, zh, k_.inv_2h[2], k_.inv_h[2])};
        }
  }

 private:
  /// samples() where every sample and both its neighbours on each axis lie inside the grid:
  /// central differences only, the same float operations as diff()'s (bit for bit), no
  /// test per sample. False (nothing written) for a brick at a border.
  bool interior_samples(const float* f, core::Sample* out, int sx, int sxy) const {
    const auto& d = vol_.grid.dims;
    int lo[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = g0_[a] + 1 + plan_.radius[a];
      if (lo[a] < 1 || lo[a] + 8 > d[a] - 2) return false;
    }
    const float ix = k_.inv_2h[0], iy = k_.inv_2h[1], iz = k_.inv_2h[2];
    for (int k = 0; k < 9; ++k)
      for (int j = 0; j < 9; ++j) {
        const float* r = f + at(lo[0] - g0_[0], lo[1] - g0_[1] + j, lo[2] - g0_[2] + k);
        core::Sample* o = out + 9 * j + 81 * k;
        for (int i = 0; i < 9; ++i)
          o[i] = {r[i], (r[i + 1] - r[i - 1]) * ix, (r[i + sx] - r[i - sx]) * iy, (r[i + sxy] - r[i - sxy]) * iz};
      }
    return true;
  }
  static float diff(int i, int n, float lo, float c, float hi, float inv_2h, float inv_h) {
    if (n < 2) return 0.0f;
    if (i == 0) return (hi - c) * inv_h;
    if (i == n - 1) return (c - lo) * inv_h;
    return (hi - lo) * inv_2h;
  }
  std::size_t at(int x, int y, int z) const {
    return (std::size_t(z) * std::size_t(S_[1]) + std::size_t(y)) * std::size_t(S_[0]) + std::size_t(x);
  }
  const Volume& vol_;
  const Plan& plan_;
  int S_[3], g0_[3] = {0, 0, 0}, vlo_[3] = {0, 0, 0}, vhi_[3] = {0, 0, 0};
  std::vector<float> buf_[2];
  int cur_ = 0;
  GradientConstants k_{};
};

CandidateCpu::CandidateCpu(const Volume& vol, const Plan& plan) : impl_(std::make_unique<BrickCpu>(vol, plan)) {}
CandidateCpu::~CandidateCpu() = default;
CandidateRange CandidateCpu::range(std::uint32_t id) {
  return impl_->range(id, core::brick_counts(impl_->grid()));
}
void CandidateCpu::samples(core::Sample* out, float background) const { impl_->samples(out, background); }

}  // namespace sparse

SparseOutput run_sparse_cpu(const Volume& vol, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                            float background, core::SampleFormat format, bool keep_input, unsigned threads,
                            const std::shared_ptr<PoolRecycler>& recycler) {
  if (std::string e = sparse::validate(passes); !e.empty()) throw std::invalid_argument("sparse chain: " + e);
  const auto t_total = std::chrono::steady_clock::now();
  SparseOutput out;
  const sparse::Plan plan = sparse::make_plan(vol.grid, passes, vol.path);

  auto t0 = std::chrono::steady_clock::now();
  const sparse::Selection sel = sparse::select(vol.grid, vol.voxels.data(), plan, iso, threads);
  out.passes.push_back({"candidate selection (raw ranges over each brick's window)", sparse::ms_since(t0), 0});

  // Candidates in contiguous parts, one thread each with its own brick buffers and pool of
  // the active ones' samples (every candidate's computation is the same whichever thread
  // runs it).
  t0 = std::chrono::steady_clock::now();
  const std::size_t nc = sel.candidates.size();
  std::vector<sparse::CandidateRange> ranges(nc);
  std::vector<const core::Sample*> where(nc, nullptr);
  const unsigned parts = threads_for(std::uint64_t(nc) * std::uint64_t(plan.region[0] * plan.region[1] * plan.region[2]), threads);
  // A part's pool is reserved for all its candidates (address space; only the pages its
  // active ones write become resident) and never zeroed (core::SamplePool): no reallocation
  // copies and no write before the samples'.
  std::vector<core::SamplePool> pools(parts);
  std::vector<std::pair<std::size_t, std::size_t>> spans;
  const std::size_t per = (nc + parts - 1) / parts;
  for (std::size_t b = 0; b < nc; b += per) spans.push_back({b, std::min(nc, b + per)});
  parallel_for(spans.size(), parts, 1, [&](std::size_t s0, std::size_t s1) {
    for (std::size_t si = s0; si < s1; ++si) {
      sparse::BrickCpu brick(vol, plan);
      core::SamplePool& pool = pools[si];
      pool.reserve((spans[si].second - spans[si].first) * std::size_t(core::kBrickSamples));
      std::vector<std::size_t> slot;
      for (std::size_t c = spans[si].first; c < spans[si].second; ++c) {
        ranges[c] = brick.range(sel.candidates[c], core::brick_counts(vol.grid));
        float tile = 0;
        if (!sparse::is_active(ranges[c], iso, background, tile)) continue;
        slot.push_back(c);
        pool.resize(pool.size() + core::kBrickSamples);
        brick.samples(pool.data() + pool.size() - core::kBrickSamples, background);
      }
      for (std::size_t i = 0; i < slot.size(); ++i) where[slot[i]] = pool.data() + i * core::kBrickSamples;
    }
  });
  out.passes.push_back({plan.text + " + gradient + min/max on candidates", sparse::ms_since(t0), 0});

  t0 = std::chrono::steady_clock::now();
  sparse::publish(vol.grid, sel, ranges, [&](std::size_t c) { return where[c]; }, iso, background, format,
                  keep_input, out, recycler);
  out.publish_ms = sparse::ms_since(t0);
  out.total_ms = sparse::ms_since(t_total);
  out.submit_wall_ms = out.total_ms;
  return out;
}

}  // namespace isotouch::engine
