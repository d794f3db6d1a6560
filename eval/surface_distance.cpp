#include "isotouch/eval/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <queue>
#include <vector>

#include "isotouch/servo/sampling.h"

namespace isotouch::eval {
using core::Vec3;
using core::finite;
namespace {
using core::Vec3;

struct Root {
  double v[8];   // corner values, bit 0 = +x, bit 1 = +y, bit 2 = +z
  Vec3 lo_m;     // world position of corner 0 [m]
};

struct Box {
  double lb;     // distance from p to the box [m]
  int root;
  double lo[3];  // local coordinates in the root cell, [0, 1]
  double size;   // local edge length (the same on every axis)
  double v[8];   // field at the 8 corners
};
struct Farther {
  bool operator()(const Box& a, const Box& b) const { return a.lb > b.lb; }
};

double trilinear(const double c[8], double u, double v, double w) {
  const double x00 = c[0] + (c[1] - c[0]) * u, x10 = c[2] + (c[3] - c[2]) * u;
  const double x01 = c[4] + (c[5] - c[4]) * u, x11 = c[6] + (c[7] - c[6]) * u;
  const double y0 = x00 + (x10 - x00) * v, y1 = x01 + (x11 - x01) * v;
  return y0 + (y1 - y0) * w;
}

// Distance from p to the axis-aligned box [lo, hi] (metres).
double box_distance(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  double s = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = p[a] < lo[a] ? lo[a] - p[a] : (p[a] > hi[a] ? p[a] - hi[a] : 0.0);
    s += d * d;
  }
  return std::sqrt(s);
}

bool straddles(const double v[8], double tau) {
  double lo = v[0], hi = v[0];
  for (int i = 1; i < 8; ++i) {
    lo = std::min(lo, v[i]);
    hi = std::max(hi, v[i]);
  }
  return lo <= tau && tau <= hi;
}

class Search {
 public:
  Search(const core::SampleField& f, double tau, const Vec3& p, double tol, std::size_t max_boxes)
      : f_(f), g_(f.grid), tau_(tau), p_(p), tol_(tol), max_boxes_(max_boxes) {}

  // Branch and bound over the cells within `radius_m` of p. Keeps best_ across calls.
  void run(double radius_m, SurfaceDistance& out) {
    roots_.clear();
    std::priority_queue<Box, std::vector<Box>, Farther> heap;
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const double q = (p_[a] - g_.origin_m[a]) / g_.spacing_m[a];
      const double r = radius_m / g_.spacing_m[a];
      lo[a] = int(std::max(0.0, std::floor(q - r)));
      hi[a] = int(std::min(double(g_.dims[a] - 2), std::floor(q + r)));
    }
    for (int k = lo[2]; k <= hi[2]; ++k)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int i = lo[0]; i <= hi[0]; ++i) {
          Root rt;
          bool finite = true;
          for (int c = 0; c < 8; ++c) {
            const double v = f_.samples[g_.index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))].value;
            finite = finite && std::isfinite(v);
            rt.v[c] = v;
          }
          if (!finite || !straddles(rt.v, tau_)) continue;
          rt.lo_m = g_.to_world({double(i), double(j), double(k)});
          const double lb = box_distance(p_, rt.lo_m, rt.lo_m + g_.spacing_m);
          if (lb > radius_m || lb >= best_ - tol_) {
            floor_ = std::min(floor_, lb);
            continue;
          }
          Box b{lb, int(roots_.size()), {0, 0, 0}, 1.0, {}};
          std::copy(rt.v, rt.v + 8, b.v);
          roots_.push_back(rt);
          heap.push(b);
        }
    while (!heap.empty()) {
      const Box b = heap.top();
      if (b.lb >= best_ - tol_) {  // every box left is at least this far
        floor_ = std::min(floor_, b.lb);
        break;
      }
      heap.pop();
      if (++out.boxes > max_boxes_) {
        out.budget_exceeded = true;
        floor_ = std::min(floor_, b.lb);
        break;
      }
      const Root& rt = roots_[std::size_t(b.root)];
      const Vec3 blo = rt.lo_m + Vec3{b.lo[0] * g_.spacing_m.x, b.lo[1] * g_.spacing_m.y, b.lo[2] * g_.spacing_m.z};
      const Vec3 ext{b.size * g_.spacing_m.x, b.size * g_.spacing_m.y, b.size * g_.spacing_m.z};
      edge_crossings(b, blo, ext);
      if (core::norm(ext) <= tol_) {  // small enough: its surface points are within tol of lb
        floor_ = std::min(floor_, b.lb);
        continue;
      }
      const double h = 0.5 * b.size;
      double v27[27];
      for (int z = 0; z < 3; ++z)
        for (int y = 0; y < 3; ++y)
          for (int x = 0; x < 3; ++x) {
            const int corner = (x == 2 ? 1 : 0) | (y == 2 ? 2 : 0) | (z == 2 ? 4 : 0);
            const bool is_corner = (x != 1) && (y != 1) && (z != 1);
            v27[(z * 3 + y) * 3 + x] = is_corner ? b.v[corner]
                                                 : trilinear(rt.v, b.lo[0] + x * h, b.lo[1] + y * h, b.lo[2] + z * h);
          }
      for (int c = 0; c < 8; ++c) {
        const int cx = c & 1, cy = (c >> 1) & 1, cz = (c >> 2) & 1;
        Box ch{0, b.root, {b.lo[0] + cx * h, b.lo[1] + cy * h, b.lo[2] + cz * h}, h, {}};
        for (int d = 0; d < 8; ++d)
          ch.v[d] = v27[((cz + ((d >> 2) & 1)) * 3 + (cy + ((d >> 1) & 1))) * 3 + (cx + (d & 1))];
        if (!straddles(ch.v, tau_)) continue;
        const Vec3 clo{rt.lo_m.x + ch.lo[0] * g_.spacing_m.x, rt.lo_m.y + ch.lo[1] * g_.spacing_m.y,
                       rt.lo_m.z + ch.lo[2] * g_.spacing_m.z};
        ch.lb = box_distance(p_, clo, clo + ext * 0.5);
        if (ch.lb >= best_ - tol_) {
          floor_ = std::min(floor_, ch.lb);
          continue;
        }
        heap.push(ch);
      }
    }
  }

  void set_tolerance(double tol) { tol_ = tol; }
  double best_ = std::numeric_limits<double>::infinity();
  Vec3 best_point_;
  double floor_ = std::numeric_limits<double>::infinity();  // smallest lower bound left unexplored

 private:
  // Exact surface points: the field is linear along every edge of a box.
  void edge_crossings(const Box& b, const Vec3& blo, const Vec3& ext) {
    for (int a = 0; a < 3; ++a) {
      const int bit = 1 << a;
      for (int c = 0; c < 8; ++c) {
        if (c & bit) continue;
        const double va = b.v[c] - tau_, vb = b.v[c | bit] - tau_;
        if (va * vb > 0) continue;
        const double t = va == vb ? 0.0 : va / (va - vb);
        double q3[3] = {blo.x + ((c & 1) ? ext.x : 0), blo.y + ((c & 2) ? ext.y : 0), blo.z + ((c & 4) ? ext.z : 0)};
        q3[a] += t * ext[a];
        const Vec3 q{q3[0], q3[1], q3[2]};
        const double d = core::norm(q - p_);
        if (d < best_) {
          best_ = d;
          best_point_ = q;
        }
      }
    }
  }

  const core::SampleField& f_;
  const core::Grid& g_;
  double tau_;
  Vec3 p_;
  double tol_;
  std::size_t max_boxes_;
  std::vector<Root> roots_;
};

}  // namespace

SurfaceDistance distance_to_isosurface(const core::SampleField& field, double tau, const Vec3& p,
                                       const SurfaceDistanceOptions& o) {
  SurfaceDistance out;
  const core::Grid& g = field.grid;
  if (g.dims[0] < 2 || g.dims[1] < 2 || g.dims[2] < 2 || field.samples.size() != g.voxel_count() ||
      !core::finite(p) || !std::isfinite(tau))
    return out;
  const double h = std::min({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z});
  const double max_r = o.max_radius_m > 0 ? o.max_radius_m : 64 * h;
  const double tol = o.tolerance_m > 0 ? o.tolerance_m : 1e-3 * h;
  Search s(field, tau, p, tol, o.max_boxes);
  double r = std::min(2 * h, max_r);
  for (;;) {
    s.floor_ = std::numeric_limits<double>::infinity();
    s.run(r, out);
    out.searched_radius_m = r;
    if (s.best_ <= r || out.budget_exceeded || r >= max_r) break;
    r = std::min(2 * r, max_r);
  }
  // Near the surface, a second pass to the relative accuracy (the first one's result is
  // the starting upper bound, so its cost is about that of the first).
  const double tol2 = std::max(o.min_tolerance_m > 0 ? o.min_tolerance_m : 1e-6 * h, o.relative_tolerance * s.best_);
  if (s.best_ <= r && !out.budget_exceeded && tol2 < tol) {
    s.set_tolerance(tol2);
    s.floor_ = std::numeric_limits<double>::infinity();
    s.run(r, out);
  }
  if (s.best_ <= r || (out.budget_exceeded && std::isfinite(s.best_))) {
    out.found = true;
    out.distance_m = s.best_;
    out.closest_m = s.best_point_;
    out.lower_bound_m = std::max(0.0, std::min({s.best_, s.floor_, r}));
  } else {
    out.lower_bound_m = r;  // nothing within the searched ball
  }
  return out;
}

double first_order_distance(const core::SampleField& field, double tau, const Vec3& p) {
  const double fv = servo::sample_value(field, p);
  const double gn = core::norm(servo::trilinear_field_gradient(field, p));
  return gn > 0 ? std::abs(fv - tau) / gn : 0.0;
}

}  // namespace isotouch::eval
