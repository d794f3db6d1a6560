// field_view.h - the one way the renderers (HRI and both baselines) read a sample field.
// Part of isotouch::core. Header-only: every accessor is inline; nothing allocates, locks
// or makes a syscall, so the servo tick can call them.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "isotouch/core/grid.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"

namespace isotouch::core {

/// Trilinear value and trilinear-interpolated gradient at a point.
struct FieldValue {
  double value = 0;  ///< trilinear value (value units); NaN where a corner is NaN
  Vec3 gradient;     ///< trilinear blend of the published gradient samples [units/m]
};

/// A read-only view of a published sample field, in the grid-world frame [m].
///
/// Interpolation: trilinear between voxel centres (index space, Grid::to_index).
///
/// Outside the grid: every voxel outside [0, n-1] on some axis has the value
/// `background()` and a zero gradient (OpenVDB's background, not clamp-to-edge). A point
/// in the one-voxel band around the grid blends the border samples with the background;
/// farther out it reads the background. With the default NaN background (SampleField)
/// everything outside the box of voxel centres reads NaN, which iso_excess() counts as
/// outside: a HIP that leaves the volume leaves the object, and an object cut by the
/// volume border ends there. With a finite outside value the border cells close the
/// object with a surface within one voxel of the last sample. (Clamp-to-edge, the rule
/// before, extended the border voxels to infinity: an object touching the border went
/// on forever, and its normals there were the border's.)
///
/// The memory seam: the only place that touches sample memory is
/// cell(): the 8 corners of an in-grid cell as a base pointer and three strides, and
/// voxel() for the checked border path. A bricked field (brick_field.h: brick table +
/// pool of 8^3 bricks stored as 9^3 samples, so a cell never straddles two bricks)
/// implements those two with one table lookup; the renderers, which only see FieldView,
/// do not change. Bricked reads: a cell belongs to the brick of its lower corner; in an
/// active brick it reads exactly the dense samples (fp32: bit-identical results), in a
/// uniform brick every corner reads the tile {tile, 0, 0, 0} (the same side of the
/// isosurface as the dense field, value constant, gradient zero); voxel() reads the
/// voxel's own brick. Compact formats decode the corners (brick_field.h gives the error).
///
/// The view holds pointers into the SampleField: it must not outlive it (the servo makes
/// one per tick from the snapshot it holds). An empty grid, fewer dense samples than
/// voxels, or an inconsistent brick store gives an empty view: NaN values, zero or NaN
/// gradients as documented per call.
class FieldView {
 public:
  FieldView() = default;
  /// The view of `f`, dense or bricked (implicit: every renderer call site passing a
  /// SampleField keeps working). A bricked field (`f.bricks` set) is read through its brick
  /// table; a dense one with fewer samples than voxels gives an empty view.
  FieldView(const SampleField& f)  // NOLINT(google-explicit-constructor)
      : grid_(f.grid), background_(f.background), version_(f.version), changed_(f.changed) {
    if (f.grid.empty()) return;
    if (f.bricks) {
      init_bricked(*f.bricks);
      return;
    }
    if (f.samples.size() >= f.grid.voxel_count()) {
      data_ = f.samples.data();
      mode_ = Mode::kDense;
      stride_[0] = 1;
      stride_[1] = std::size_t(f.grid.dims[0]);
      stride_[2] = std::size_t(f.grid.dims[0]) * std::size_t(f.grid.dims[1]);
      for (int a = 0; a < 3; ++a) {
        last_[a] = double(f.grid.dims[a] - 1);
        step_[a] = f.grid.dims[a] > 1 ? stride_[a] : 0;
      }
    }
  }

  const Grid& grid() const { return grid_; }
  /// Value of every voxel outside the grid (see class docs).
  float background() const { return background_; }
  bool empty() const { return mode_ == Mode::kEmpty; }
  /// The snapshot's SampleField::version (an edit publishes version + 1; the
  /// renderers tell a new snapshot by it). 0 for a default-constructed view.
  std::uint64_t version() const { return version_; }
  /// What changed since the previous version (SampleField::changed; unknown for a default view).
  const SampleField::ChangedBox& changed() const { return changed_; }
  /// Reads a brick table (bricked field) rather than a dense array.
  bool bricked() const { return mode_ >= Mode::kBricked; }

  /// Trilinear value at `world_m` (grid-world [m]); NaN if not finite or empty.
  /// The servo's hot path (HRI reads values only).
  double value(const Vec3& world_m) const {
    if (empty()) return kNaN;
    return value_at_index_nonempty(grid_.to_index(world_m));
  }

  /// Trilinear value and trilinear blend of the gradient samples at `world_m`.
  /// NaN value (zero gradient) if not finite or empty.
  FieldValue value_gradient(const Vec3& world_m) const {
    FieldValue out;
    if (empty()) {
      out.value = kNaN;
      return out;
    }
    const Vec3 idx = grid_.to_index(world_m);
    if (in_grid(idx)) {
      // Fast path: one cell lookup; the same weights and order as the border path.
      int i0[3];
      double f[3];
      for (int a = 0; a < 3; ++a) inner(idx[a], grid_.dims[a], i0[a], f[a]);
      Sample scratch[8];
      const CellRef c = cell(i0[0], i0[1], i0[2], scratch);
      double v = 0, gx = 0, gy = 0, gz = 0;
      for (int k = 0; k < 2; ++k) {
        const double wz = k ? f[2] : 1.0 - f[2];
        for (int j = 0; j < 2; ++j) {
          const double wy = j ? f[1] : 1.0 - f[1];
          for (int i = 0; i < 2; ++i) {
            const double w = (i ? f[0] : 1.0 - f[0]) * wy * wz;
            const Sample& s = c.base[(i ? c.sx : 0) + (j ? c.sy : 0) + (k ? c.sz : 0)];
            v += w * s.value;
            gx += w * s.gx;
            gy += w * s.gy;
            gz += w * s.gz;
          }
        }
      }
      out.value = v;
      out.gradient = {gx, gy, gz};
      return out;
    }
    Corner c[3];
    if (!locate(idx, c)) {
      out.value = kNaN;
      return out;
    }
    double v = 0, gx = 0, gy = 0, gz = 0;
    for (int k = 0; k < 2; ++k) {
      const double wz = k ? c[2].f : 1.0 - c[2].f;
      const int z = k ? c[2].i1 : c[2].i0;
      for (int j = 0; j < 2; ++j) {
        const double wy = j ? c[1].f : 1.0 - c[1].f;
        const int y = j ? c[1].i1 : c[1].i0;
        for (int i = 0; i < 2; ++i) {
          const double w = (i ? c[0].f : 1.0 - c[0].f) * wy * wz;
          const Sample s = voxel(i ? c[0].i1 : c[0].i0, y, z);
          v += w * s.value;
          gx += w * s.gx;
          gy += w * s.gy;
          gz += w * s.gz;
        }
      }
    }
    out.value = v;
    out.gradient = {gx, gy, gz};
    return out;
  }

  /// Central differences of the trilinear value at `world_m` with half steps h [m] per
  /// axis: ((f(x + h_x e_x) - f(x - h_x e_x)) / (2 h_x), ...) [units/m], the six points
  /// taken in index space from one to_index (the paper's SurfaceNormal, §2). NaN
  /// components if not finite or empty.
  Vec3 central_difference(const Vec3& world_m, const Vec3& h_m) const {
    if (empty()) return {kNaN, kNaN, kNaN};
    const Vec3 hi{h_m.x / grid_.spacing_m.x, h_m.y / grid_.spacing_m.y, h_m.z / grid_.spacing_m.z};
    return central_difference_at(grid_.to_index(world_m), hi, h_m);
  }
  /// central_difference with half-voxel steps (h = spacing / 2, the paper's SurfaceNormal),
  /// bit for bit: the index steps h / spacing are 0.5 exactly, so they are not divided out.
  [[gnu::always_inline]] Vec3 central_difference_half_voxel(const Vec3& world_m) const {
    if (empty()) return {kNaN, kNaN, kNaN};
    return central_difference_at(grid_.to_index(world_m), {0.5, 0.5, 0.5}, grid_.spacing_m * 0.5);
  }

 private:
  /// central_difference at index idx with index steps hi (= h_m / spacing).
  [[gnu::always_inline]] Vec3 central_difference_at(const Vec3& idx, const Vec3& hi, const Vec3& h_m) const {
    const double x0 = idx.x - hi.x, x1 = idx.x + hi.x, y0 = idx.y - hi.y, y1 = idx.y + hi.y,
                 z0 = idx.z - hi.z, z1 = idx.z + hi.z;
    Vec3 g;
    if (mode_ == Mode::kDense && central_dense(idx, {x0, y0, z0}, {x1, y1, z1}, h_m, g)) return g;
    if (mode_ == Mode::kBricked && central_bricked(idx, {x0, y0, z0}, {x1, y1, z1}, h_m, g)) return g;
    return central_point_by_point(idx, {x0, y0, z0}, {x1, y1, z1}, h_m);
  }
  /// central_difference's six points read one by one (the border, cells not shared).
  [[gnu::noinline]] Vec3 central_point_by_point(const Vec3& idx, const Vec3& lo, const Vec3& hi, const Vec3& h_m) const {
    return {(value_at_index({hi.x, idx.y, idx.z}) - value_at_index({lo.x, idx.y, idx.z})) / (2 * h_m.x),
            (value_at_index({idx.x, hi.y, idx.z}) - value_at_index({idx.x, lo.y, idx.z})) / (2 * h_m.y),
            (value_at_index({idx.x, idx.y, hi.z}) - value_at_index({idx.x, idx.y, lo.z})) / (2 * h_m.z)};
  }

 public:

  /// Exact gradient of the trilinear value field at `world_m` (derivative of the
  /// interpolant, piecewise bilinear) [units/m], background included. Zero if the point
  /// is not finite or the view is empty. Used by error metrics and reference runs.
  Vec3 trilinear_gradient(const Vec3& world_m) const {
    Corner c[3];
    if (empty()) return {};
    const Vec3 idx = grid_.to_index(world_m);
    if (!locate(idx, c)) return {};
    // In the grid: the corners of cell() (the cell value() interpolates); border: voxel().
    const bool fast = in_grid(idx);
    Sample scratch[8];
    CellRef cr{nullptr, 0, 0, 0};
    if (fast) cr = cell(c[0].i0, c[1].i0, c[2].i0, scratch);
    double d[3] = {0, 0, 0};
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          const double v = fast ? cr.base[(i ? cr.sx : 0) + (j ? cr.sy : 0) + (k ? cr.sz : 0)].value
                                : voxel(i ? c[0].i1 : c[0].i0, j ? c[1].i1 : c[1].i0, k ? c[2].i1 : c[2].i0).value;
          const double wx = i ? c[0].f : 1 - c[0].f, wy = j ? c[1].f : 1 - c[1].f,
                       wz = k ? c[2].f : 1 - c[2].f;
          const double sx = i ? 1.0 : -1.0, sy = j ? 1.0 : -1.0, sz = k ? 1.0 : -1.0;
          d[0] += sx * wy * wz * v;
          d[1] += wx * sy * wz * v;
          d[2] += wx * wy * sz * v;
        }
    return {d[0] / grid_.spacing_m.x, d[1] / grid_.spacing_m.y, d[2] / grid_.spacing_m.z};
  }

  /// The in-grid cell whose trilinear interpolant value() reads at `world_m`, for a point
  /// at least 1e-9 voxel inside the cell on every axis: its box shrunk by that margin
  /// (grid-world [m]; every point of the box reads this cell while to_index rounds to well
  /// below the margin: indices and origin / spacing under about 1e6) and the least and largest of
  /// its 8 corner values, so that value() anywhere in the box lies in [lo_value, hi_value]
  /// to rounding (a convex blend of the corners). False for a point off the box of voxel
  /// centres or within the margin of a cell face, a non-finite point or corner, a 1-voxel
  /// axis, an empty view. Lets the servo skip reads that cannot find the isosurface.
  bool cell_range(const Vec3& world_m, Vec3& lo_m, Vec3& hi_m, double& lo_value, double& hi_value) const {
    if (empty()) return false;
    const Vec3 idx = grid_.to_index(world_m);
    int i0[3];
    for (int a = 0; a < 3; ++a)
      if (!in_one_cell(idx[a], idx[a], a, i0[a])) return false;
    Sample scratch[8];
    const CellRef c = cell(i0[0], i0[1], i0[2], scratch);
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          const double v = c.base[(i ? c.sx : 0) + (j ? c.sy : 0) + (k ? c.sz : 0)].value;
          if (!std::isfinite(v)) return false;
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
    const Vec3 a = grid_.to_world({double(i0[0]), double(i0[1]), double(i0[2])});
    const Vec3 b = grid_.to_world({double(i0[0] + 1), double(i0[1] + 1), double(i0[2] + 1)});
    const Vec3 m = grid_.spacing_m * (2 * kCellMargin);  // the margin, doubled for the rounding of a, b
    lo_m = a + m;
    hi_m = b - m;
    lo_value = lo;
    hi_value = hi;
    return true;
  }
  /// The storage the view reads (dense samples or brick table): two views of one snapshot
  /// version read the same values iff they share it.
  const void* storage() const { return mode_ == Mode::kDense ? static_cast<const void*>(data_) : static_cast<const void*>(table_); }

  /// A bound on |value(p) - value(q)| for any two points p, q of the segment a -> b
  /// (grid-world [m]) that lies strictly inside one in-grid cell (1e-9 voxel from its faces),
  /// rounding of the reads included: inside a cell the trilinear value's slope along an
  /// axis is a blend of the cell's four edge differences along it, so it changes by at most
  /// the largest of them times the segment's extent along that axis [voxels] (plus 1e-9
  /// voxel for the rounding of the points' positions); the rounding of two reads adds less
  /// than 1e-12 of the largest corner. +inf where the segment leaves the cell or the grid's
  /// box of voxel centres, or a corner is not finite. Lets a caller skip reads whose outcome
  /// the bound decides (HRI's god-object test).
  double change_bound_in_cell(const Vec3& a_m, const Vec3& b_m) const {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    if (empty()) return kInf;
    // Indices by products with the reciprocal spacing (no division on the caller's chain):
    // they differ from to_index's (and Segment's reads') by a few ulps of the index, inside
    // the 1e-9 voxel margin while indices are below about 1e6 (as cell_range's margin).
    const Vec3& sp = grid_.spacing_m;
    const Vec3 inv{1.0 / sp.x, 1.0 / sp.y, 1.0 / sp.z};
    const Vec3 da = a_m - grid_.origin_m, db = b_m - grid_.origin_m;
    const Vec3 ia{da.x * inv.x, da.y * inv.y, da.z * inv.z}, ib{db.x * inv.x, db.y * inv.y, db.z * inv.z};
    int i0[3];
    double ext[3];
    for (int a = 0; a < 3; ++a) {
      // (std::min / std::max would drop a NaN second argument: compare explicitly)
      if (!(std::isfinite(ia[a]) && std::isfinite(ib[a]))) return kInf;
      const double lo = ia[a] < ib[a] ? ia[a] : ib[a], hi = ia[a] < ib[a] ? ib[a] : ia[a];
      if (!in_one_cell(lo, hi, a, i0[a])) return kInf;
      ext[a] = hi - lo + kCellMargin;
    }
    Sample scratch[8];
    const CellRef c = cell(i0[0], i0[1], i0[2], scratch);
    double v[8];
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) v[i + 2 * j + 4 * k] = c.base[(i ? c.sx : 0) + (j ? c.sy : 0) + (k ? c.sz : 0)].value;
    double sum = 0, big = 0, slope[3] = {0, 0, 0};
    for (int l = 0; l < 8; ++l) {
      sum += v[l];
      big = std::max(big, std::abs(v[l]));
    }
    if (!std::isfinite(sum)) return kInf;  // a NaN or infinite corner (or an overflow: no bound)
    for (int e = 0; e < 4; ++e) {  // the e-th edge along each axis: its lower corner's index
      const int x0 = 2 * e, y0 = (e & 1) + 4 * (e >> 1), z0 = e;
      slope[0] = std::max(slope[0], std::abs(v[x0 + 1] - v[x0]));
      slope[1] = std::max(slope[1], std::abs(v[y0 + 2] - v[y0]));
      slope[2] = std::max(slope[2], std::abs(v[z0 + 4] - v[z0]));
    }
    return slope[0] * ext[0] + slope[1] * ext[1] + slope[2] * ext[2] + 1e-12 * big;
  }

  /// Values along one segment a -> b (grid-world [m]) at parameters t: the trilinear value
  /// at the continuous index ia + (ib - ia) t, with ia, ib the ends' indices (one to_index
  /// each, not one per read). Along a line the trilinear interpolant of one cell is a cubic
  /// in t: a read in a new in-grid cell loads its corners and the cubic's coefficients, about
  /// the read's place (with the t interval the line spends in the cell), and every later read
  /// in that interval is three multiply-adds (a march of fifth-voxel steps reads each cell
  /// about five times, a root search more). Within rounding of value_at_index of that index:
  /// the cubic's terms are bounded by the corners (each fraction moves at most 1 within the
  /// cell), so the two differ by a few ulps of the largest corner. Points off the box of voxel
  /// centres, and non-finite ones, read value_at_index (the border path). The index of a
  /// point differs from to_index(a + (b - a) t) by rounding only. Must not outlive the view.
  class Segment {
   public:
    Segment(const FieldView& v, const Vec3& a_m, const Vec3& b_m)
        : v_(v), ia_(v.grid_.to_index(a_m)), d_(v.grid_.to_index(b_m) - ia_) {}
    /// The value at parameter t (t = 0: a, t = 1: b, to rounding); NaN where value() is
    /// (a NaN corner, a non-finite point, an empty view).
    [[gnu::always_inline]] double value(double t) {
      if (t >= t_lo_ && t <= t_hi_) {
        const double s = t - t0_;
        return ((p_[3] * s + p_[2]) * s + p_[1]) * s + p_[0];
      }
      return load(t);
    }

   private:
    /// The cell of the point at t: its cubic about t and its t interval; the value at t.
    [[gnu::noinline]] double load(double t) {
      const Vec3 idx{ia_.x + d_.x * t, ia_.y + d_.y * t, ia_.z + d_.z * t};
      t_lo_ = 1.0;
      t_hi_ = 0.0;  // no interval until a cell is loaded
      if (v_.empty() || !v_.in_grid(idx)) return v_.value_at_index(idx);
      int i0[3];
      double f[3];
      inner(idx.x, v_.grid_.dims[0], i0[0], f[0]);
      inner(idx.y, v_.grid_.dims[1], i0[1], f[1]);
      inner(idx.z, v_.grid_.dims[2], i0[2], f[2]);
      Sample scratch[8];
      const CellRef c = v_.cell(i0[0], i0[1], i0[2], scratch);
      double k[8];  // corner (i, j, k) at i + 2 j + 4 k
      for (int z = 0; z < 2; ++z)
        for (int y = 0; y < 2; ++y)
          for (int x = 0; x < 2; ++x) k[x + 2 * y + 4 * z] = c.base[(x ? c.sx : 0) + (y ? c.sy : 0) + (z ? c.sz : 0)].value;
      // v = k0 + kx X + ky Y + kz Z + kxy XY + kxz XZ + kyz YZ + kxyz XYZ with the fractions
      // X = f.x + d.x s (s = t - t0) on a 1-voxel axis: its fraction stays 0.
      const double kx = k[1] - k[0], ky = k[2] - k[0], kz = k[4] - k[0];
      const double kxy = k[3] - k[1] - k[2] + k[0], kxz = k[5] - k[1] - k[4] + k[0], kyz = k[6] - k[2] - k[4] + k[0];
      const double kxyz = k[7] - k[6] - k[5] - k[3] + k[1] + k[2] + k[4] - k[0];
      double b[3];
      for (int a = 0; a < 3; ++a) b[a] = v_.grid_.dims[a] > 1 ? d_[a] : 0.0;
      const double xy[3] = {f[0] * f[1], f[0] * b[1] + b[0] * f[1], b[0] * b[1]};
      const double xz[3] = {f[0] * f[2], f[0] * b[2] + b[0] * f[2], b[0] * b[2]};
      const double yz[3] = {f[1] * f[2], f[1] * b[2] + b[1] * f[2], b[1] * b[2]};
      const double xyz[4] = {xy[0] * f[2], xy[0] * b[2] + xy[1] * f[2], xy[1] * b[2] + xy[2] * f[2], xy[2] * b[2]};
      p_[0] = k[0] + kx * f[0] + ky * f[1] + kz * f[2] + kxy * xy[0] + kxz * xz[0] + kyz * yz[0] + kxyz * xyz[0];
      p_[1] = kx * b[0] + ky * b[1] + kz * b[2] + kxy * xy[1] + kxz * xz[1] + kyz * yz[1] + kxyz * xyz[1];
      p_[2] = kxy * xy[2] + kxz * xz[2] + kyz * yz[2] + kxyz * xyz[2];
      p_[3] = kxyz * xyz[3];
      // The t interval in the cell: each fraction in [0, 1] (a 1-voxel axis: any t).
      double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
      for (int a = 0; a < 3; ++a) {
        if (b[a] == 0.0) {
          // A 1-voxel axis the line crosses: in the grid only where its index is 0 (this t).
          if (d_[a] != 0.0) {
            lo = hi = t;
            break;
          }
          continue;
        }
        const double t_at0 = t - f[a] / b[a], t_at1 = t + (1.0 - f[a]) / b[a];
        lo = std::max(lo, std::min(t_at0, t_at1));
        hi = std::min(hi, std::max(t_at0, t_at1));
      }
      t0_ = t;
      if (lo <= t && t <= hi) {  // (NaN: no interval, every read loads)
        t_lo_ = lo;
        t_hi_ = hi;
      }
      return p_[0];
    }

    const FieldView& v_;
    Vec3 ia_, d_;
    double t_lo_ = 1.0, t_hi_ = 0.0;  ///< the loaded cell's t interval (empty: none loaded)
    double t0_ = 0.0;                 ///< the t the cubic is about
    double p_[4] = {};                ///< the cubic in t - t0_, constant term first
  };

  /// Trilinear value at a continuous index (voxel centres at integers); NaN if not
  /// finite or empty.
  double value_at_index(const Vec3& idx) const {
    if (empty()) return kNaN;
    return value_at_index_nonempty(idx);
  }

  /// Voxel (x, y, z): the sample if it is in the grid, else {background, 0, 0, 0}.
  /// Bricked: read from the voxel's own brick (the pool, decoded, or {tile, 0, 0, 0}).
  /// Requires a non-empty view.
  Sample voxel(int x, int y, int z) const {
    if (x < 0 || y < 0 || z < 0 || x >= grid_.dims[0] || y >= grid_.dims[1] || z >= grid_.dims[2])
      return {background_, 0.f, 0.f, 0.f};
    if (mode_ == Mode::kDense)
      return data_[std::size_t(x) + std::size_t(y) * stride_[1] + std::size_t(z) * stride_[2]];
    const std::uint32_t e = brick_entry(x, y, z);
    if (e & BrickStore::kUniform) return tiles_[e & ~BrickStore::kUniform];
    const std::size_t i = std::size_t(e) + local_offset(x, y, z);
    return mode_ != Mode::kBrickedCompact ? data_[i] : store_->decode_compact(compact_[i], BrickStore::slot_of(e));
  }

 private:
  /// value_at_index on a non-empty view: the in-grid fast path inline, the border out of line.
  [[gnu::always_inline]] double value_at_index_nonempty(const Vec3& idx) const {
    if (in_grid(idx)) {
      // Fast path: the whole cell is in the grid. One cell lookup, seven lerps.
      int i0[3];
      double f[3];
      inner(idx.x, grid_.dims[0], i0[0], f[0]);
      inner(idx.y, grid_.dims[1], i0[1], f[1]);
      inner(idx.z, grid_.dims[2], i0[2], f[2]);
      if (mode_ == Mode::kDense)
        return trilinear(data_ + std::size_t(i0[0]) + std::size_t(i0[1]) * stride_[1] + std::size_t(i0[2]) * stride_[2],
                         step_[0], step_[1], step_[2], f);
      if (mode_ == Mode::kBricked) return value_bricked(i0[0], i0[1], i0[2], f);
      Sample scratch[8];
      const CellRef c = cell(i0[0], i0[1], i0[2], scratch);
      return trilinear(c.base, c.sx, c.sy, c.sz, f);
    }
    return value_border(idx);
  }
  /// The trilinear value of the cell whose corner (i, j, k) is s[i sx + j sy + k sz], at
  /// fractions f: four x-lerps, two y-lerps, one z-lerp (every in-grid read, dense or bricked).
  [[gnu::always_inline]] static double trilinear(const Sample* s, std::size_t sx, std::size_t sy, std::size_t sz,
                                                 const double (&f)[3]) {
    const double c00 = lerp(s[0].value, s[sx].value, f[0]);
    const double c10 = lerp(s[sy].value, s[sy + sx].value, f[0]);
    const double c01 = lerp(s[sz].value, s[sz + sx].value, f[0]);
    const double c11 = lerp(s[sz + sy].value, s[sz + sy + sx].value, f[0]);
    return lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2]);
  }
  /// value_at_index's in-grid cell (lower corner (x, y, z), fractions f) on an fp32 bricked field
  /// with no 1-voxel axis: the cell strides are the constants (1, 9, 81), so the corners
  /// are fixed offsets from one pointer; a uniform brick's cell reads its tile at every
  /// corner, which is the same seven lerps of one value (not the value itself: the lerps
  /// turn -0 into +0 and an infinite tile into NaN, as the corner-by-corner reads do).
  [[gnu::always_inline]] double value_bricked(int x, int y, int z, const double (&f)[3]) const {
    const std::uint32_t e = brick_entry(x, y, z);
    if (e & BrickStore::kUniform) {
      const double t = tiles_[e & ~BrickStore::kUniform].value;
      const double c = lerp(t, t, f[0]);  // c00 = c10 = c01 = c11
      const double cy = lerp(c, c, f[1]);
      return lerp(cy, cy, f[2]);
    }
    return trilinear(data_ + std::size_t(e) + local_offset(x, y, z), 1, kBrickStored,
                     kBrickStored * kBrickStored, f);
  }
  /// The border path of value_at_index: corners outside the grid read the background.
  [[gnu::noinline]] double value_border(const Vec3& idx) const {
    Corner c[3];
    if (!locate(idx, c)) return kNaN;
    // Border path: corners outside the grid read the background. Same lerps.
    auto v = [&](int i, int j, int k) {
      return double(voxel(i ? c[0].i1 : c[0].i0, j ? c[1].i1 : c[1].i0, k ? c[2].i1 : c[2].i0).value);
    };
    const double c00 = lerp(v(0, 0, 0), v(1, 0, 0), c[0].f);
    const double c10 = lerp(v(0, 1, 0), v(1, 1, 0), c[0].f);
    const double c01 = lerp(v(0, 0, 1), v(1, 0, 1), c[0].f);
    const double c11 = lerp(v(0, 1, 1), v(1, 1, 1), c[0].f);
    return lerp(lerp(c00, c10, c[1].f), lerp(c01, c11, c[1].f), c[2].f);
  }

  /// The cells of central_difference's six points when they share them: the points
  /// (c.x, lo.y | hi.y, c.z) and (c.x, c.y, lo.z | hi.z) read the same column pair with the
  /// same x fraction, so their x-lerps over a 3 x 3 block of rows and layers can be
  /// computed once (central_reads). False unless every point lies in the box of voxel
  /// centres below its upper face (where `inner` would clamp) and the rows / layers of each
  /// pair are consecutive (steps other than about half a voxel): the caller then reads the
  /// six points one by one.
  struct CentralCells {
    int cx, cy, cz, lx, ly, lz, hx;  ///< lower corners: centre, low point, high x point (hy = ly + 1, hz = lz + 1)
    double fcx, fcy, fcz, flx, fly, flz, fhx, fhy, fhz;  ///< fractions of the centre, the low and the high points
  };
  bool central_cells(const Vec3& c, const Vec3& lo, const Vec3& hi, CentralCells& k) const {
    if (!(lo.x >= 0.0 && lo.y >= 0.0 && lo.z >= 0.0 && hi.x < last_[0] && hi.y < last_[1] && hi.z < last_[2] &&
          lo.x <= c.x && lo.y <= c.y && lo.z <= c.z && c.x <= hi.x && c.y <= hi.y && c.z <= hi.z))
      return false;
    // inner() of a coordinate in [0, n - 1): the lower corner int(v), the fraction v - int(v).
    const int cx = int(c.x), cy = int(c.y), cz = int(c.z), lx = int(lo.x), ly = int(lo.y), lz = int(lo.z),
              hx = int(hi.x), hy = int(hi.y), hz = int(hi.z);
    // Rows (y) and layers (z) of the y and z pairs: l, l + 1 = h, l + 2; the centre's pair
    // (c, c + 1) among them (l <= c <= h, as lo <= c <= hi).
    if (hy != ly + 1 || hz != lz + 1) return false;
    k = {cx, cy, cz, lx, ly, lz, hx, c.x - cx, c.y - cy, c.z - cz, lo.x - lx, lo.y - ly, lo.z - lz,
         hi.x - hx, hi.y - hy, hi.z - hz};
    return true;
  }
  /// central_difference from the shared cells `k`: voxel (x, y, z) of the block read is
  /// at b + (x - cx) sx + (y - ly) sy + (z - lz) sz, and s0 / s1 are the corners (lx | hx,
  /// cy, cz) of the x pair's cells. Every point's value is the lerps value_at_index would
  /// take, in its order (the same bits).
  [[gnu::always_inline]] static Vec3 central_reads(const Sample* b, const Sample* s0, const Sample* s1,
                                                   std::size_t sx, std::size_t sy, std::size_t sz,
                                                   const CentralCells& k, const Vec3& h_m) {
    const int dj = k.cy - k.ly, dk = k.cz - k.lz;
    // x-lerps at column cx (fraction fcx), rows ly + r, layers lz + l.
    double xl[3][3];
    for (int r = 0; r < 3; ++r)
      for (int l = 0; l < 3; ++l) {
        const Sample* s = b + std::size_t(r) * sy + std::size_t(l) * sz;
        xl[r][l] = lerp(s[0].value, s[sx].value, k.fcx);
      }
    const double vy0 = lerp(lerp(xl[0][dk], xl[1][dk], k.fly), lerp(xl[0][dk + 1], xl[1][dk + 1], k.fly), k.fcz);
    const double vy1 = lerp(lerp(xl[1][dk], xl[2][dk], k.fhy), lerp(xl[1][dk + 1], xl[2][dk + 1], k.fhy), k.fcz);
    const double mid = lerp(xl[dj][1], xl[dj + 1][1], k.fcy);
    const double vz0 = lerp(lerp(xl[dj][0], xl[dj + 1][0], k.fcy), mid, k.flz);
    const double vz1 = lerp(mid, lerp(xl[dj][2], xl[dj + 1][2], k.fcy), k.fhz);
    // The x pair: columns lx and hx with their own fractions, the centre's rows and layers.
    const double v0 = trilinear(s0, sx, sy, sz, {k.flx, k.fcy, k.fcz});
    const double v1 = trilinear(s1, sx, sy, sz, {k.fhx, k.fcy, k.fcz});
    return {(v1 - v0) / (2 * h_m.x), (vy1 - vy0) / (2 * h_m.y), (vz1 - vz0) / (2 * h_m.z)};
  }
  /// central_difference on a dense field where the six points share their cells
  /// (central_cells); false (nothing written) where they do not.
  [[gnu::always_inline]] bool central_dense(const Vec3& c, const Vec3& lo, const Vec3& hi, const Vec3& h_m, Vec3& g) const {
    CentralCells k;
    if (!central_cells(c, lo, hi, k)) return false;
    const std::size_t sy = stride_[1], sz = stride_[2];
    const Sample* b = data_ + std::size_t(k.cx) + std::size_t(k.ly) * sy + std::size_t(k.lz) * sz;
    const Sample* bx = data_ + std::size_t(k.cy) * sy + std::size_t(k.cz) * sz;
    g = central_reads(b, bx + std::size_t(k.lx), bx + std::size_t(k.hx), 1, sy, sz, k, h_m);
    return true;
  }
  /// The same on an fp32 bricked field with no 1-voxel axis. Where every cell of the six
  /// points lies in one brick, one table lookup: an active brick's stored samples (strides
  /// 1, 9, 81), or a uniform brick's tile at every corner (strides 0: the lerps
  /// value_at_index takes there). Where the cells span two bricks (a pair's lower corners
  /// on either side of a brick face: about a third of the points at half-voxel steps, and
  /// every point of a stroke along a brick face), each point's cell is read from its own
  /// brick (value_bricked), its corners and fractions taken from `k` as value_at_index
  /// would find them.
  bool central_bricked(const Vec3& c, const Vec3& lo, const Vec3& hi, const Vec3& h_m, Vec3& g) const {
    CentralCells k;
    if (!central_cells(c, lo, hi, k)) return false;
    // lx <= cx <= hx, ly <= cy <= ly + 1, lz <= cz <= lz + 1: one brick iff each pair's
    // ends share their brick index (i >> 3).
    if (((k.lx ^ k.hx) | (k.ly ^ (k.ly + 1)) | (k.lz ^ (k.lz + 1))) >> 3) {
      g = central_cellwise(k, h_m);
      return true;
    }
    const std::uint32_t e = brick_entry(k.cx, k.cy, k.cz);
    if (e & BrickStore::kUniform) {
      const Sample* t = tiles_ + (e & ~BrickStore::kUniform);
      g = central_reads(t, t, t, 0, 0, 0, k, h_m);
      return true;
    }
    const Sample* p = data_ + std::size_t(e);
    g = central_reads(p + local_offset(k.cx, k.ly, k.lz), p + local_offset(k.lx, k.cy, k.cz),
                      p + local_offset(k.hx, k.cy, k.cz), 1, kBrickStored, kBrickStored * kBrickStored, k, h_m);
    return true;
  }
  /// central_bricked's six points, each from its own cell and brick.
  [[gnu::noinline]] Vec3 central_cellwise(const CentralCells& k, const Vec3& h_m) const {
    const double x0 = value_bricked(k.lx, k.cy, k.cz, {k.flx, k.fcy, k.fcz});
    const double x1 = value_bricked(k.hx, k.cy, k.cz, {k.fhx, k.fcy, k.fcz});
    const double y0 = value_bricked(k.cx, k.ly, k.cz, {k.fcx, k.fly, k.fcz});
    const double y1 = value_bricked(k.cx, k.ly + 1, k.cz, {k.fcx, k.fhy, k.fcz});
    const double z0 = value_bricked(k.cx, k.cy, k.lz, {k.fcx, k.fcy, k.flz});
    const double z1 = value_bricked(k.cx, k.cy, k.lz + 1, {k.fcx, k.fcy, k.fhz});
    return {(x1 - x0) / (2 * h_m.x), (y1 - y0) / (2 * h_m.y), (z1 - z0) / (2 * h_m.z)};
  }

  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  /// One axis of a cell: lower and upper corner index and the fraction toward the upper.
  struct Corner {
    int i0, i1;
    double f;
  };
  /// The 8 corners of an in-grid cell: corner (i, j, k) is base[i*sx + j*sy + k*sz].
  struct CellRef {
    const Sample* base;
    std::size_t sx, sy, sz;
  };

  static double lerp(double a, double b, double t) { return a + t * (b - a); }
  /// How far inside its cell (cell_range, change_bound_in_cell) a point must lie [voxels].
  static constexpr double kCellMargin = 1e-9;
  /// Indices [lo, hi] on axis a lie in one in-grid cell, at least kCellMargin inside it on
  /// that axis: its lower corner in i0. False off the box of voxel centres (a 1-voxel axis:
  /// last_ = 0), within the margin of a face, or NaN.
  bool in_one_cell(double lo, double hi, int a, int& i0) const {
    if (!(lo >= kCellMargin && hi <= last_[a] - kCellMargin)) return false;
    i0 = int(lo);
    return lo - kCellMargin >= double(i0) && hi + kCellMargin <= double(i0 + 1);
  }
  /// v within the box of voxel centres [0, n-1] (false for NaN).
  static bool in_range(double v, int n) { return v >= 0.0 && v <= double(n - 1); }
  /// The index lies in the box of voxel centres on every axis (false for NaN).
  bool in_grid(const Vec3& i) const {
    return i.x >= 0.0 && i.x <= last_[0] && i.y >= 0.0 && i.y <= last_[1] && i.z >= 0.0 && i.z <= last_[2];
  }
  /// In-range axis: lower corner (the last cell holds v = n-1 with f = 1) and fraction.
  static void inner(double v, int n, int& i0, double& f) {
    i0 = int(v);
    if (i0 >= n - 1) i0 = std::max(n - 2, 0);
    f = n > 1 ? v - i0 : 0.0;
  }
  /// Any finite index: corners and fraction per axis (a 1-voxel axis in range uses
  /// voxel 0 twice); false if a coordinate is not finite. Far outside, the coordinate is
  /// clamped to 2 voxels beyond the grid, where both corners are background anyway.
  bool locate(const Vec3& idx, Corner c[3]) const {
    for (int a = 0; a < 3; ++a) {
      const int n = grid_.dims[a];
      double v = idx[a];
      if (!std::isfinite(v)) return false;
      if (in_range(v, n)) {
        inner(v, n, c[a].i0, c[a].f);
        c[a].i1 = n > 1 ? c[a].i0 + 1 : c[a].i0;
      } else {
        v = std::clamp(v, -2.0, double(n) + 1.0);
        c[a].i0 = int(std::floor(v));
        c[a].i1 = c[a].i0 + 1;
        c[a].f = v - c[a].i0;
      }
    }
    return true;
  }
  /// The memory seam (see class docs): the in-grid cell with lower corner (x, y, z).
  /// Dense: a pointer into the samples. Bricked (one table lookup, the cell's brick is the
  /// one holding its lower corner): an active brick gives a pointer into its 9^3 stored
  /// samples, strides (1, 9, 81); a uniform one its tile, strides 0. Compact formats decode
  /// the 8 corners into `scratch`, strides (1, 2, 4). A 1-voxel axis has stride 0 (dense
  /// and bricked alike: its upper corner has weight 0 and is never read).
  [[gnu::always_inline]] CellRef cell(int x, int y, int z, Sample (&scratch)[8]) const {
    if (mode_ == Mode::kDense)
      return {data_ + std::size_t(x) + std::size_t(y) * stride_[1] + std::size_t(z) * stride_[2], step_[0], step_[1],
              step_[2]};
    const std::uint32_t e = brick_entry(x, y, z);
    if (e & BrickStore::kUniform) return {tiles_ + (e & ~BrickStore::kUniform), 0, 0, 0};
    const std::size_t i = std::size_t(e) + local_offset(x, y, z);
    if (mode_ == Mode::kBricked) return {data_ + i, 1, kBrickStored, kBrickStored * kBrickStored};
    if (mode_ == Mode::kBrickedThin) return {data_ + i, step_[0], step_[1], step_[2]};
    return decode_cell(BrickStore::slot_of(e), i, scratch);
  }
  /// Compact formats: the 8 corners of the cell at pool index `i` of slot `slot`, decoded.
  [[gnu::noinline]] CellRef decode_cell(std::uint32_t slot, std::size_t i, Sample (&scratch)[8]) const {
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 2; ++j)
        for (int l = 0; l < 2; ++l)
          scratch[l + 2 * j + 4 * k] =
              store_->decode_compact(compact_[i + (l ? step_[0] : 0) + (j ? step_[1] : 0) + (k ? step_[2] : 0)], slot);
    return {scratch, 1, 2, 4};
  }
  /// Table entry of the brick holding in-grid voxel (x, y, z).
  std::uint32_t brick_entry(int x, int y, int z) const {
    return table_[std::size_t(z >> 3) * nbxy_ + std::size_t(y >> 3) * nbx_ + std::size_t(x >> 3)];
  }
  /// Offset of voxel (x, y, z) in its brick's stored samples: i + 9 j + 81 k.
  static std::size_t local_offset(int x, int y, int z) {
    return std::size_t(x & 7) + std::size_t(kBrickStored) * std::size_t(y & 7) +
           std::size_t(kBrickStored * kBrickStored) * std::size_t(z & 7);
  }
  /// Set up the bricked mode from the store's sealed read pointers (BrickStore::seal
  /// checked the table and pool lengths once); an unsealed store, or one sealed for other
  /// dims than this field's grid, gives an empty view. Runs once per tick.
  void init_bricked(const BrickStore& b) {
    const BrickStore::Sealed& s = b.sealed();
    if (s.table == nullptr || s.dims[0] != grid_.dims[0] || s.dims[1] != grid_.dims[1] || s.dims[2] != grid_.dims[2])
      return;
    data_ = s.pool;
    table_ = s.table;
    tiles_ = s.tiles;
    nbx_ = s.nbx;
    nbxy_ = s.nbxy;
    for (int a = 0; a < 3; ++a) last_[a] = double(grid_.dims[a] - 1);
    if (s.pool != nullptr && !s.thin) {
      mode_ = Mode::kBricked;  // the cell strides are constants: step_ is not read
      return;
    }
    mode_ = s.pool == nullptr ? Mode::kBrickedCompact : Mode::kBrickedThin;
    compact_ = s.compact;
    store_ = &b;
    const std::size_t st[3] = {1, kBrickStored, kBrickStored * kBrickStored};
    for (int a = 0; a < 3; ++a) step_[a] = grid_.dims[a] > 1 ? st[a] : 0;
  }

  /// kBricked: fp32 bricks, every axis longer than 1 voxel (cell strides 1, 9, 81, known
  /// at compile time); kBrickedThin: fp32 bricks with a 1-voxel axis (its stride is 0:
  /// cell strides from step_); kBrickedCompact: kFp16 / kUnorm16 bricks, decoded per cell.
  /// The bricked modes last (bricked()).
  enum class Mode : std::uint8_t { kEmpty, kDense, kBricked, kBrickedThin, kBrickedCompact };

  Grid grid_;
  Mode mode_ = Mode::kEmpty;
  const Sample* data_ = nullptr;       ///< dense: the samples; kBricked, kBrickedThin: the fp32 pool
  std::size_t stride_[3] = {0, 0, 0};  ///< dense: x (always 1), y, z element strides
  std::size_t step_[3] = {0, 0, 0};    ///< cell strides (dense: stride; kBrickedThin, kBrickedCompact: 1, 9, 81), 0 on a 1-voxel axis
  double last_[3] = {-1, -1, -1};      ///< n - 1 per axis (the box of voxel centres)
  float background_ = std::numeric_limits<float>::quiet_NaN();
  std::uint64_t version_ = 0;          ///< SampleField::version of the viewed snapshot
  SampleField::ChangedBox changed_;   ///< SampleField::changed of the viewed snapshot
  // Bricked mode (BrickStore): the table, the tiles, the compact pool and its decoder.
  const std::uint32_t* table_ = nullptr;
  const Sample* tiles_ = nullptr;
  const CompactSample* compact_ = nullptr;
  const BrickStore* store_ = nullptr;
  std::size_t nbx_ = 0, nbxy_ = 0;     ///< bricks along x; along x times along y
};

}  // namespace isotouch::core
