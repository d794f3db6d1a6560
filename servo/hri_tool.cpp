// hri_tool.cpp - the spherical tool, not in the paper (which renders a point): the HIP is
// the centre of a sphere of radius r, and the proxy is kept outside several intermediate
// planes at once (god-object with several active constraints), HRI's one virtual plane
// generalised. The planes come from a scan of the trilinear cells near the proxy
// (surface_scan) or, for a tool of many voxels, from Newton searches (nearest_surface).
// hri.h, "Spherical tool".

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "isotouch/servo/sampling.h"

namespace isotouch::servo {

Vec3 HriRenderer::tool_solve(const Vec3& hip) const {
  // min |x - hip| subject to n_i . (x - p_i) >= r: the optimum is the projection of the HIP
  // onto the intersection of some active subset (KKT: x = hip + sum l_j n_j, l_j >= 0);
  // every subset's projection that is feasible is a candidate, the nearest wins.
  const double r = params_.tool_radius_m;
  const int m = tool_plane_count_;
  const ToolPlane* pl = tool_planes_;
  const double tol = 1e-9;
  auto feasible = [&](const Vec3& x) {
    for (int i = 0; i < m; ++i)
      if (dot(pl[i].n, x - pl[i].p) < r - tol) return false;
    return true;
  };
  if (feasible(hip)) return hip;
  Vec3 best = hip;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int mask = 1; mask < (1 << m); ++mask) {
    int idx[3];
    int k = 0;
    for (int i = 0; i < m && k <= 3; ++i)
      if (mask & (1 << i)) {
        if (k < 3) idx[k] = i;
        ++k;
      }
    if (k > 3) continue;  // at most 3 independent constraints in 3-D
    double b[3], l[3] = {0, 0, 0};
    for (int i = 0; i < k; ++i) b[i] = r - dot(pl[idx[i]].n, hip - pl[idx[i]].p);
    auto g = [&](int i, int j) { return dot(pl[idx[i]].n, pl[idx[j]].n); };
    if (k == 1) {
      l[0] = b[0];
    } else if (k == 2) {
      const double a = g(0, 0), c = g(0, 1), d = g(1, 1);
      const double det = a * d - c * c;
      if (!(std::abs(det) > 1e-9)) continue;
      l[0] = (b[0] * d - c * b[1]) / det;
      l[1] = (a * b[1] - c * b[0]) / det;
    } else {
      const double a00 = g(0, 0), a01 = g(0, 1), a02 = g(0, 2), a11 = g(1, 1), a12 = g(1, 2), a22 = g(2, 2);
      const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
      const double det = a00 * c00 + a01 * c01 + a02 * c02;
      if (!(std::abs(det) > 1e-9)) continue;
      const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
      l[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det;
      l[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det;
      l[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det;
    }
    bool ok = true;
    Vec3 x = hip;
    for (int i = 0; i < k; ++i) {
      if (!(l[i] >= -tol)) ok = false;
      x = x + pl[idx[i]].n * l[i];
    }
    if (!ok || !feasible(x)) continue;
    const Vec3 dx = x - hip;
    const double d2 = dot(dx, dx);
    if (d2 < best_d2) {
      best_d2 = d2;
      best = x;
    }
  }
  if (std::isfinite(best_d2)) return best;
  // No feasible subset (planes that no sphere of radius r fits between): project onto
  // the violated planes in turn, a few rounds.
  Vec3 x = hip;
  for (int round = 0; round < 8; ++round)
    for (int i = 0; i < m; ++i) {
      const double v = r - dot(pl[i].n, x - pl[i].p);
      if (v > 0) x = x + pl[i].n * v;
    }
  return x;
}

void HriRenderer::set_tool_radius(double r) {
  const double old = params_.tool_radius_m;
  if (params_.variant != Variant::kRobust || !std::isfinite(r) || r < 0.0 || r == old) return;
  // The proxy that touches the same surface point with the new radius: a sphere's centre
  // moves along its first plane's normal by the change; a point's proxy (on its plane)
  // moves out by r; a sphere becoming a point keeps its centre outside, so that the point's
  // next tick finds its contact on the way to the HIP, as a first contact does.
  Vec3 proxy = vhip_;
  if (old > 0.0 && r > 0.0 && tool_plane_count_ > 0) proxy = vhip_ + tool_planes_[0].n * (r - old);
  else if (!(old > 0.0) && plane_.valid) proxy = vhip_ + plane_.n * r;
  // What was sent, and the hand's velocity, outlive the contact state.
  const Vec3 sent = prev_force_, v = v_filt_;
  const double sent_mag = prev_force_mag_;
  const bool contact = was_contact_, vel = vel_valid_;
  clear_contact();
  prev_force_ = sent;
  prev_force_mag_ = sent_mag;
  prev_target_f_ = sent;  // the next update's step is measured from the force sent
  was_contact_ = contact;  // no contact at the next tick: the release fade from `sent`
  v_filt_ = v;
  vel_valid_ = vel;
  ramp_ref_ = {};
  vhip_ = proxy;
  vhip_value_known_ = false;
  vhip_outside_ = false;
  params_.tool_radius_m = r;
  quick_ok_ = quick_covered();
  plain_ = false;
  tool_reseat_ = r > 0.0;
}

bool HriRenderer::nearest_surface(const FieldView& field, const Vec3& x, double reach, Vec3& q,
                                  Vec3& n) const {
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const Isosurface iso{params_.tau, params_.inside};
  // Newton steps along the gradient from `from`: y <- y + N e / |grad| (e the excess, N
  // outward), each at most one voxel long, at most `steps` reads; true when on the surface.
  auto newton = [&](Vec3 from, int steps, Vec3& y) {
    y = from;
    for (int k = 0; k < steps; ++k) {
      const FieldValue s = sample_trilinear(field, y);
      const double e = excess(s.value);
      const Vec3 go = iso.outward(s.gradient);
      const double gn = norm(go);
      if (!std::isfinite(s.value) || !(gn > 0) || !std::isfinite(gn)) return false;
      const double step = std::clamp(e / gn, -voxel, voxel);
      y = y + go * (step / gn);
      const Vec3 moved = y - x;
      if (dot(moved, moved) > reach * reach) return false;
      if (std::abs(step) < 1e-3 * voxel) return true;
    }
    return false;
  };
  Vec3 y;
  bool found = newton(x, 8, y);
  if (!found) {
    // March along the normal at x (inward when x is outside, outward when inside),
    // half-voxel steps within reach, then 20 bisection steps.
    const bool in = excess(sample_value(field, x)) > 0.0;
    const Vec3 n0 = outward_normal(field, x, Vec3{0.0, 0.0, 1.0});
    const Vec3 dir = in ? n0 : n0 * -1.0;
    const double h = 0.5 * voxel;
    const int steps = std::max(1, int(std::ceil(reach / h)));
    double lo = 0.0;
    for (int i = 1; i <= steps && !found; ++i) {
      const double t = std::min(reach, h * i);
      const bool inside = excess(sample_value(field, x + dir * t)) > 0.0;
      if (inside != in) {
        double hi = t;
        for (int k = 0; k < 20; ++k) {
          const double mid = 0.5 * (lo + hi);
          ((excess(sample_value(field, x + dir * mid)) > 0.0) == in ? lo : hi) = mid;
        }
        y = x + dir * (in ? hi : lo);  // the outside end of the bracket
        found = true;
      }
      lo = t;
    }
    if (!found) return false;
  }
  n = outward_normal(field, y, normalized_or(x - y, Vec3{0.0, 0.0, 1.0}));
  // A gradient path ends near, not at, the nearest point of a curved surface: twice, slide
  // to the foot of x on the tangent plane and come back to the surface (Newton again).
  for (int round = 0; round < 2; ++round) {
    const Vec3 off = x - y;
    const Vec3 tangential = off - n * dot(n, off);
    if (!(dot(tangential, tangential) > 1e-6 * voxel * voxel)) break;
    Vec3 y2;
    if (!newton(y + tangential, 4, y2)) break;
    y = y2;
    n = outward_normal(field, y, n);
  }
  q = y;
  return finite(q) && finite(n);
}

void HriRenderer::tool_rebuild_newton(const FieldView& field, const Vec3& hip) {
  // 1. The surface point nearest the proxy of the tick before gives the first plane.
  // 2. A held plane that proxy still touches (within a quarter voxel), that faces another
  //    way than every new plane (more than 15 deg) and whose wall is still there (inside a
  //    quarter voxel behind its point) is another wall of a groove or a corner: it stays
  //    (else the proxy, moved toward the HIP under the new plane alone, could cross into it).
  // 3. While the proxy moved toward the HIP under the planes so far is still closer than r
  //    to the surface, the point nearest it gives the next plane. At most three.
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double tol = 1e-3 * voxel;
  const double reach = 1.8 * r + voxel;
  ToolPlane held[kMaxToolPlanes];
  const int held_count = tool_plane_count_;
  std::copy(tool_planes_, tool_planes_ + held_count, held);
  tool_plane_count_ = 0;
  auto add = [&](const Vec3& n, const Vec3& q) {
    for (int j = 0; j < tool_plane_count_; ++j)
      if (dot(tool_planes_[j].n, n) > 0.9999 && std::abs(dot(tool_planes_[j].n, q - tool_planes_[j].p)) < tol)
        return false;  // the same plane
    tool_planes_[tool_plane_count_++] = {n, q};
    return true;
  };
  // A point farther than r + 1 voxel from where it was searched is not the wall in
  // contact (a gradient path through a drilled cavity can end anywhere within reach).
  auto near = [&](const Vec3& from, const Vec3& q) {
    const Vec3 d = q - from;
    return dot(d, d) <= (r + voxel) * (r + voxel);
  };
  Vec3 q, n;
  if (nearest_surface(field, vhip_, reach, q, n) && near(vhip_, q)) add(n, q);
  const double cos15 = 0.9659;
  for (int i = 0; i < held_count && tool_plane_count_ < 3; ++i) {
    if (!(dot(held[i].n, vhip_ - held[i].p) < r + 0.25 * voxel)) continue;
    // ... and only where the wall is still there (an edit may have removed it).
    if (!(excess(sample_value(field, held[i].p - held[i].n * (0.25 * voxel))) > 0.0)) continue;
    bool other = true;
    for (int j = 0; j < tool_plane_count_; ++j)
      if (dot(tool_planes_[j].n, held[i].n) > cos15) other = false;
    if (other) add(held[i].n, held[i].p);
  }
  while (tool_plane_count_ > 0 && tool_plane_count_ < 3) {
    const Vec3 x = tool_solve(hip);
    bool added = false;
    if (nearest_surface(field, x, reach, q, n) && near(x, q) && dot(n, x - q) < r - tol) added = add(n, q);
    if (!added) {
      // A gradient path from x can end on a farther sheet (a crease, a thin wall): also
      // from the point of the sphere that leads toward the HIP, if it is inside.
      const Vec3 to_hip = hip - x;
      const double l = norm(to_hip);
      const Vec3 lead = l > 0 ? x + to_hip * (r / l) : x;
      if (l > 0 && excess(sample_value(field, lead)) > 0.0 && nearest_surface(field, lead, reach, q, n) &&
          near(x, q) && dot(n, x - q) < r - tol)
        added = add(n, q);
    }
    if (!added) break;  // the proxy is clear of the surface
  }
}

namespace {
/// Trilinear excess and its gradient [1/m] at u in [0,1]^3 (cell fractions) of a cell of
/// size `sp` [m] whose corners hold the excess `e` (corner c = i + 2 j + 4 k).
[[gnu::always_inline]] inline double cell_excess(const double (&e)[8], const Vec3& sp, const Vec3& u, Vec3& g) {
  const double x0 = 1 - u.x, y0 = 1 - u.y, z0 = 1 - u.z;
  const double e00 = e[0] * x0 + e[1] * u.x, e10 = e[2] * x0 + e[3] * u.x;
  const double e01 = e[4] * x0 + e[5] * u.x, e11 = e[6] * x0 + e[7] * u.x;
  const double e0 = e00 * y0 + e10 * u.y, e1 = e01 * y0 + e11 * u.y;
  g.x = ((e[1] - e[0]) * y0 * z0 + (e[3] - e[2]) * u.y * z0 + (e[5] - e[4]) * y0 * u.z + (e[7] - e[6]) * u.y * u.z) /
        sp.x;
  g.y = ((e10 - e00) * z0 + (e11 - e01) * u.z) / sp.y;
  g.z = (e1 - e0) / sp.z;
  return e0 * z0 + e1 * u.z;
}
/// A point y [m] relative to the cell's lower corner as cell fractions, clamped to the cell.
[[gnu::always_inline]] inline Vec3 cell_fractions(const Vec3& y, const Vec3& sp) {
  return Vec3{std::clamp(y.x / sp.x, 0.0, 1.0), std::clamp(y.y / sp.y, 0.0, 1.0), std::clamp(y.z / sp.z, 0.0, 1.0)};
}

/// One round of nearest_in_cell's projection from u (cell fractions; `ya` the point [m],
/// `ev` and `g` the excess and its gradient there): X - lambda g on the patch linearised at
/// u, a component at a face of the cell whose target lies beyond it held there (lambda
/// solving the patch over the free ones). `passes` > 1 re-tests the face components against
/// the last pass's lambda, holding or freeing them. The next point (fractions, clamped) in
/// `next`; false where no free gradient is left.
bool project_on_patch(const double (&xa)[3], const double (&ya)[3], const Vec3& u, double ev, const Vec3& g,
                      const Vec3& sp, int passes, Vec3& next) {
  const double gv[3] = {g.x, g.y, g.z}, uv[3] = {u.x, u.y, u.z};
  double ga[3] = {g.x, g.y, g.z}, xa2[3] = {xa[0], xa[1], xa[2]};
  double g2 = dot(g, g);
  if (!(g2 > 0)) return false;
  double l2 = ev + g.x * (xa[0] - ya[0]) + g.y * (xa[1] - ya[1]) + g.z * (xa[2] - ya[2]);  // lambda = l2 / g2
  bool held[3] = {false, false, false};
  for (int pass = 0; pass < passes; ++pass) {
    bool changed = false;
    for (int a = 0; a < 3; ++a) {
      if (!(uv[a] <= 0.0 || uv[a] >= 1.0)) continue;  // not at a face of the cell on this axis: free
      const double t = xa[a] - gv[a] * l2 / g2;
      const bool beyond = (uv[a] <= 0.0 && t < 0.0) || (uv[a] >= 1.0 && t > sp[a]);
      changed = changed || beyond != held[a];
      held[a] = beyond;
    }
    if (pass > 0 && !changed) break;
    for (int a = 0; a < 3; ++a) {
      ga[a] = held[a] ? 0.0 : gv[a];
      xa2[a] = held[a] ? ya[a] : xa[a];
    }
    g2 = ga[0] * ga[0] + ga[1] * ga[1] + ga[2] * ga[2];
    if (!(g2 > 0)) return false;
    l2 = ev + ga[0] * (xa2[0] - ya[0]) + ga[1] * (xa2[1] - ya[1]) + ga[2] * (xa2[2] - ya[2]);
  }
  next = cell_fractions({xa2[0] - ga[0] * l2 / g2, xa2[1] - ga[1] * l2 / g2, xa2[2] - ga[2] * l2 / g2}, sp);
  return true;
}

/// The point of one trilinear cell's surface nearest X (surface_scan): `e` the excess at the
/// cell's corners (corner c = i + 2 j + 4 k), X and the result relative to the lower corner
/// [m], `sp` the cell's size [m]. The nearest edge crossing (an exact surface point: the
/// field is linear along an edge), then projections of X onto the patch linearised at the
/// current point (y <- X - g (e + g . (X - y)) / |g|^2, clamped to the cell, at most 10
/// rounds) from the cell point nearest X and from that crossing; a projection that lands
/// on the patch (|e| < tol |g|) and is nearer replaces the crossing.
struct CellPoint {
  Vec3 best;                                              ///< the nearest point found
  double best_d2 = std::numeric_limits<double>::infinity();  ///< its squared distance (inf: none)
  bool converged = false;                                 ///< a projection landed on the patch
};
CellPoint nearest_in_cell(const double (&e)[8], const double (&xa)[3], const Vec3& sp, double tol) {
  const Vec3 X{xa[0], xa[1], xa[2]};
  auto eval = [&](const Vec3& u, Vec3& g) { return cell_excess(e, sp, u, g); };
  auto clamp_u = [&](const Vec3& y) { return cell_fractions(y, sp); };
  // The nearest edge crossing.
  Vec3 best;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const int step = 1 << a;
    for (int c = 0; c < 8; ++c) {
      if (c & step) continue;
      const double ea = e[c], eb = e[c + step];
      if ((ea > 0.0) == (eb > 0.0)) continue;
      double ya[3] = {double(c & 1) * sp.x, double((c >> 1) & 1) * sp.y, double(c >> 2) * sp.z};
      ya[a] = sp[a] * (ea / (ea - eb));
      const Vec3 y{ya[0], ya[1], ya[2]};
      const Vec3 d = X - y;
      if (dot(d, d) < best_d2) {
        best_d2 = dot(d, d);
        best = y;
      }
    }
  }
  // Projections onto the linearised patch from the cell point nearest x; a component
  // held at a face of the cell (the target beyond it) stays there and the others
  // solve the linearised problem on that face.
  // Two starts: the cell point nearest x, and the nearest edge crossing (a cell may
  // hold two sheets of a saddle).
  bool converged = false;
  Vec3 g;
  const Vec3 starts[2] = {clamp_u(X), std::isfinite(best_d2) ? clamp_u(best) : clamp_u(X)};
  for (int start = 0; start < (std::isfinite(best_d2) ? 2 : 1); ++start) {
    Vec3 u = starts[start];
    for (int it = 0; it < 10; ++it) {
      const double ya[3] = {u.x * sp.x, u.y * sp.y, u.z * sp.z};
      const double ev = eval(u, g);
      Vec3 next;
      if (!project_on_patch(xa, ya, u, ev, g, sp, 1, next)) break;
      // Stalled at a cell face: the faces re-tested against the projection of the free
      // axes alone (on a long cell's edge a short axis's gradient, held, no longer pushes the
      // long axis beyond its face: the nearest point inside the cell, not its edge crossing),
      // taken where it moves the point by more than the tolerance.
      if (next.x == u.x && next.y == u.y && next.z == u.z) {
        Vec3 freed;
        if (!project_on_patch(xa, ya, u, ev, g, sp, 4, freed)) break;
        const Vec3 step{(freed.x - u.x) * sp.x, (freed.y - u.y) * sp.y, (freed.z - u.z) * sp.z};
        if (dot(step, step) > tol * tol) next = freed;
      }
      // A fixed point: every further round would compute the same u (the rounds are a
      // function of u alone), so stopping here gives the same point in fewer rounds.
      if (next.x == u.x && next.y == u.y && next.z == u.z) break;
      u = next;
    }
    {
      const Vec3 y{u.x * sp.x, u.y * sp.y, u.z * sp.z};
      const double ev = eval(u, g);
      const double gn = norm(g);
      const Vec3 d = X - y;
      const bool on = gn > 0 && std::abs(ev) < tol * gn;
      converged = converged || on;
      if (on && dot(d, d) < best_d2) {
        best_d2 = dot(d, d);
        best = y;
      }
    }
  }
  CellPoint out;
  out.best = best;
  out.best_d2 = best_d2;
  out.converged = converged;
  return out;
}

}  // namespace

bool HriRenderer::surface_scan(const FieldView& field, const Vec3& x, double reach) {
  // Every cell whose box lies within `reach` of x: the trilinear field on a cell lies
  // between its corners' extremes, so the cell holds the surface exactly when its corners
  // straddle tau (a NaN corner: no surface, as everywhere in the servo). In such a cell
  // its point nearest x (nearest_in_cell). The kMaxScanPoints nearest points are kept.
  const Grid& grid = field.grid();
  const Vec3& sp = grid.spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const Vec3 ix = grid.to_index(x);
  if (!finite(ix) || !(reach > 0)) return false;
  int lo[3], n[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = int(std::floor(ix[a] - reach / sp[a]));
    n[a] = int(std::ceil(ix[a] + reach / sp[a])) - lo[a] + 1;  // samples on this axis
    if (n[a] > kScanSide || n[a] < 2) return false;
  }
  // Per axis and cell c along it: x relative to the cell's lower corner [m] (xa) and the
  // square of its distance outside the cell's extent (out2), so that a cell's squared box
  // distance is out2 x + out2 y + out2 z; per sample, the least out2 of its two cells (near2).
  double xa_of[3][kScanSide], out2[3][kScanSide], near2[3][kScanSide];
  for (int a = 0; a < 3; ++a) {
    for (int c = 0; c + 1 < n[a]; ++c) {
      xa_of[a][c] = (ix[a] - double(lo[a] + c)) * sp[a];
      const double out = std::max({0.0, -xa_of[a][c], xa_of[a][c] - sp[a]});
      out2[a][c] = out * out;
    }
    near2[a][0] = out2[a][0];
    for (int c = 1; c + 1 < n[a]; ++c) near2[a][c] = std::min(out2[a][c - 1], out2[a][c]);
    near2[a][n[a] - 1] = out2[a][n[a] - 2];
  }
  const double reach2 = reach * reach;
  // The samples of the cells within reach (a sample whose every cell is farther is left
  // NaN: no cell reads it). The sums are rounded as the cells' box distances are, and
  // each term is at most the cell's, so no sample a cell within reach needs is skipped.
  // Each sample's class: 1 inside, 2 outside, 4 not finite (or not read); a cell holds
  // the surface exactly when its corners' classes together are 3.
  std::uint8_t cls[kScanSide * kScanSide * kScanSide];
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        const int at = (k * n[1] + j) * n[0] + i;
        float& to = scan_excess_[at];
        if (near2[0][i] + near2[1][j] + near2[2][k] > reach2) {
          to = std::nanf("");
          cls[at] = 4;
          continue;
        }
        const double v = field.value_at_index({double(lo[0] + i), double(lo[1] + j), double(lo[2] + k)});
        to = std::isfinite(v) ? float(excess(v)) : std::nanf("");
        cls[at] = !std::isfinite(to) ? 4 : to > 0.0f ? 1 : 2;
      }
  scan_count_ = 0;
  scan_clear_m_ = reach;
  const double tol = 1e-3 * voxel;
  const bool x_outside = !(excess(field.value(x)) > 0.0);
  auto keep = [&](const Vec3& q, const Vec3& n_out, double d) {
    if (scan_count_ == kMaxScanPoints) {
      int far = 0;
      for (int c = 1; c < scan_count_; ++c)
        if (scan_[c].d > scan_[far].d) far = c;
      if (!(d < scan_[far].d)) return;
      scan_[far] = {q, n_out, d};
    } else {
      scan_[scan_count_++] = {q, n_out, d};
    }
  };
  for (int ck = 0; ck + 1 < n[2]; ++ck)
    for (int cj = 0; cj + 1 < n[1]; ++cj)
      for (int ci = 0; ci + 1 < n[0]; ++ci) {
        // The cell's box distance (squared).
        const double box2 = out2[0][ci] + out2[1][cj] + out2[2][ck];
        if (box2 > reach2) continue;
        const int c0 = (ck * n[1] + cj) * n[0] + ci, sy = n[0], sz = n[0] * n[1];
        if ((cls[c0] | cls[c0 + 1] | cls[c0 + sy] | cls[c0 + sy + 1] | cls[c0 + sz] | cls[c0 + sz + 1] |
             cls[c0 + sz + sy] | cls[c0 + sz + sy + 1]) != 3)
          continue;
        double e[8];
        for (int c = 0; c < 8; ++c) e[c] = scan_excess_[c0 + (c >> 2) * sz + ((c >> 1) & 1) * sy + (c & 1)];
        const double xa[3] = {xa_of[0][ci], xa_of[1][cj], xa_of[2][ck]};
        const CellPoint cp = nearest_in_cell(e, xa, sp, tol);
        if (!std::isfinite(cp.best_d2)) continue;
        const Vec3& best = cp.best;
        const double dist = std::sqrt(cp.best_d2);
        const Vec3 q = grid.to_world(
            {double(lo[0] + ci) + best.x / sp.x, double(lo[1] + cj) + best.y / sp.y, double(lo[2] + ck) + best.z / sp.z});
        // The plane's normal: toward x from an x outside (the nearest point's normal, and
        // defined at creases); the outward gradient where x is inside or on the surface.
        Vec3 n_out;
        if (x_outside && dist > tol) {
          n_out = (x - q) / dist;
        } else {
          Vec3 gq;  // the excess gradient at the point (clamped to the cell)
          cell_excess(e, sp, cell_fractions(best, sp), gq);
          n_out = normalized_or(gq * -1.0, normalized_or(x - q, Vec3{0.0, 0.0, 1.0}));
        }
        keep(q, n_out, dist);
        // The free-motion clearance: the point found where the projections converged, else
        // the cell's box distance (a proven lower bound).
        scan_clear_m_ = std::min(scan_clear_m_, cp.converged ? dist : std::sqrt(box2));
      }
  // Nearest first: a stable insertion sort of the kept points' order (at most
  // kMaxScanPoints), then the points moved once into that order.
  std::uint8_t order[kMaxScanPoints];
  for (int a = 0; a < scan_count_; ++a) {
    int b = a;
    for (; b > 0 && scan_[a].d < scan_[order[b - 1]].d; --b) order[b] = order[b - 1];
    order[b] = std::uint8_t(a);
  }
  ScanPoint sorted[kMaxScanPoints];
  for (int a = 0; a < scan_count_; ++a) sorted[a] = scan_[order[a]];
  std::copy(sorted, sorted + scan_count_, scan_);
  return true;
}

int HriRenderer::tool_add_uncovered(const Vec3& x, double reach, double voxel) {
  // A scanned point behind a held plane, or on it to 0.01 voxel, cannot come nearer than
  // r (less that) to a proxy the plane holds; every other point within reach adds a plane
  // through it facing x (nearest first).
  const double cover = 0.01 * voxel;
  int added = 0;
  for (int c = 0; c < scan_count_ && tool_plane_count_ < kMaxToolPlanes; ++c) {
    const ScanPoint& s = scan_[c];
    if (s.d > reach) break;
    bool covered = false;
    for (int i = 0; i < tool_plane_count_ && !covered; ++i)
      covered = dot(tool_planes_[i].n, s.q - tool_planes_[i].p) < cover;
    if (covered) continue;
    const double d = norm(x - s.q);
    const Vec3 n = d > 1e-3 * voxel && dot(x - s.q, s.n) > 0 ? (x - s.q) / d : s.n;
    tool_planes_[tool_plane_count_++] = {n, s.q};
    ++added;
  }
  return added;
}

void HriRenderer::tool_rebuild(const FieldView& field, const Vec3& hip) {
  // The planes from scans of the cells around the proxy (see the class docs); a tool too
  // large for the scan box: Newton searches (tool_rebuild_newton).
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double reach = r + voxel;
  Vec3 centre = vhip_;
  scan_valid_ = false;
  for (int pass = 0; pass < 3; ++pass) {
    if (!surface_scan(field, centre, reach)) {
      if (pass == 0) tool_rebuild_newton(field, hip);
      return;
    }
    if (pass == 0) tool_plane_count_ = 0;
    tool_add_uncovered(centre, reach, voxel);
    anchor_ = centre;
    scan_valid_ = true;
    const Vec3 y = tool_plane_count_ > 0 ? tool_solve(hip) : hip;
    const Vec3 moved = y - centre;
    if (dot(moved, moved) <= 0.0625 * voxel * voxel) break;
    centre = y;
  }
}

bool HriRenderer::tool_near_material(const FieldView& field, const Vec3& hip, double voxel, Vec3& m, bool& have_m) {
  // The sphere at the HIP overlaps the material: the HIP is inside (m = the HIP), or a
  // surface point nearer than r is found (m: a point inside just behind it): by the Newton
  // search from the HIP (nearest_surface), else by the scan of the cells within r of it
  // (surface_scan, its clearance: a lower bound where a cell's projections did not
  // converge). Each misses what the other finds: beside a fin's trilinear edge the gradient
  // path ends on the face's far part (the blended gradient samples turn there), and a
  // projection on the long cells of 1 x 1 x 3 mm voxels stops short of the nearest point.
  have_m = excess(sample_value(field, hip)) > 0.0;
  if (have_m) {
    m = hip;
    return true;
  }
  const double r = params_.tool_radius_m;
  Vec3 q, n;
  // The scan's points are scratch; the clearance and its validity (free motion, edits) stay
  // the last update's.
  const bool valid = scan_valid_;
  const double clear = scan_clear_m_;
  const bool scanned = surface_scan(field, hip, r);
  const bool found = nearest_surface(field, hip, r + voxel, q, n) && dot(q - hip, q - hip) < r * r;
  const bool near = found || (scanned && scan_count_ > 0 && scan_clear_m_ < r);
  if (!found && near) {
    q = scan_[0].q;
    n = scan_[0].n;
  }
  scan_valid_ = valid;
  scan_clear_m_ = clear;
  if (!near) return false;
  // Just behind q, away from the HIP, else against the outward normal at q (a thin
  // feature's trilinear inside can be a sliver, and at a tip the two differ); none on a
  // speck of material.
  const Vec3 dirs[2] = {n, outward_normal(field, q, n)};
  for (const Vec3& d : dirs)
    for (const double behind : {0.02, 0.05, 0.1, 0.2}) {
      m = q - d * (behind * voxel);
      have_m = excess(sample_value(field, m)) > 0.0;
      if (have_m) return true;
    }
  return true;
}

bool HriRenderer::tool_past_middle(const FieldView& field, const Vec3& m, const Vec3& hip, const Vec3& n,
                                   double reach, double voxel) const {
  // The chord of material through m along n (fifth-voxel steps both ways, at most
  // march_budget samples in all; both ends within reach: a feature, not a half-space), and
  // the HIP's level along n against its middle: past it, or short of it by no more than
  // half the point's quarter voxel of slack (past_middle: the same test from the HIP).
  const int steps = chord_steps(reach, voxel);
  const double step = reach / steps;
  const int slack = int(std::ceil(0.25 * voxel / step));
  FieldView::Segment down(field, m, m - n * reach), up(field, m, m + n * reach);
  int down_out = 0, up_out = 0;  // the steps where the material ends (0: not within reach)
  material_ends(down, up, steps, down_out, up_out);
  return down_out > 0 && up_out > 0 && 2.0 * dot(n, hip - m) <= double(up_out - down_out + slack) * step;
}

void HriRenderer::tool_hold_entry_side(const FieldView& field, const Vec3& hip, bool holding, const ToolPlane* kept,
                                       int kept_count, Vec3& solved) {
  // The point's hold_entry_side for the sphere (see the class docs, "Spherical tool"): the
  // push direction stands for the plane's normal, the sphere overlapping the material for
  // the HIP inside, and the chord through the material nearest the HIP for the line
  // through the HIP.
  static const double kCos = std::cos(kEntryConeDeg * M_PI / 180.0);
  const Vec3 push = solved - hip;
  const double pen = norm(push);
  if (!holding) {  // a new contact (or new material, a new radius): its side
    entry_n_ = pen > 0.0 ? push / pen : (tool_plane_count_ > 0 ? tool_planes_[0].n : Vec3{});
    entry_held_ = false;
    return;
  }
  // Clear of every new plane (the sphere slipped off an edge toward the far side) counts as
  // a turn: held as one where the sphere still overlaps the material.
  const Vec3 u = pen > 0.0 ? push / pen : entry_n_;
  const bool turned = !(pen > 0.0) || dot(u, entry_n_) < kCos;
  if (!turned && !entry_held_) return;  // the common update: no read
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  Vec3 m;
  bool have_m = false;
  if (!tool_near_material(field, hip, voxel, m, have_m)) {
    entry_held_ = false;  // the sphere left the material: the side is free again
    if (turned) entry_n_ = u;
    return;
  }
  if (!turned) return;
  // The planes of the tick before that face the entry side (a plane across the stroke, a
  // tip's, would drag), with the new ones that do not face away from it (the near surface
  // the proxy slides onto: a one-voxel plate's next blob), and the proxy they give this HIP.
  ToolPlane fresh[kMaxToolPlanes];
  const int fresh_count = tool_plane_count_;
  std::copy(tool_planes_, tool_planes_ + fresh_count, fresh);
  tool_plane_count_ = 0;
  for (int i = 0; i < kept_count; ++i)
    if (dot(kept[i].n, entry_n_) >= kCos) tool_planes_[tool_plane_count_++] = kept[i];
  const int entry_side = tool_plane_count_;
  for (int i = 0; i < fresh_count && tool_plane_count_ < kMaxToolPlanes; ++i)
    if (dot(fresh[i].n, entry_n_) > 0.0) tool_planes_[tool_plane_count_++] = fresh[i];
  const Vec3 held = entry_side > 0 ? tool_solve(hip) : hip;
  const double held_pen = norm(held - hip);
  const double reach = 2.0 * std::max(0.0, held_pen - params_.tool_radius_m) + voxel;
  if (held_pen > 0.0 && (entry_held_ || (have_m && tool_past_middle(field, m, hip, entry_n_, reach, voxel)))) {
    entry_held_ = true;  // the held planes stay: the proxy on the entry side
    scan_valid_ = false;
    solved = held;
    return;
  }
  std::copy(fresh, fresh + fresh_count, tool_planes_);
  tool_plane_count_ = fresh_count;
  entry_n_ = u;
}

Vec3 HriRenderer::tool_tick(const FieldView& field, const Vec3& hip, bool edited, TickOut& out) {
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const bool reseat = tool_reseat_;
  bool update = reseat || (edited && (tool_plane_count_ > 0 || was_contact_));
  tool_reseat_ = false;
  if (edited) scan_valid_ = false;  // the last scan's clearance was of the old snapshot
  // The proxy for the planes held now (tool_solve, a few dozen small solves), computed once
  // a tick: the planes change only at an update.
  Vec3 solved;
  bool have_solved = false;
  if (tool_plane_count_ > 0 && !update) {
    bool held = false;  // does any plane hold the HIP?
    for (int i = 0; i < tool_plane_count_; ++i)
      if (dot(tool_planes_[i].n, hip - tool_planes_[i].p) < r) held = true;
    if (!held) {
      tool_plane_count_ = 0;  // clear of every plane: free motion (tested below)
    } else {
      solved = tool_solve(hip);
      have_solved = true;
      const Vec3 slide = solved - anchor_;
      // Early when the proxy is 0.2 voxel from the scan's centre: the scan covered the
      // surface within r + 1 voxel of it, and a tangent plane held over a curved (or,
      // between voxels, wavy trilinear) surface lets the sphere sink by about
      // slide^2 * curvature / 2.
      if (++c_ >= params_.plane_update_period || dot(slide, slide) > 0.04 * voxel * voxel) update = true;
    }
  }
  if (tool_plane_count_ == 0 && !update && scan_valid_) {
    // Free motion after a scan: no surface is nearer to its centre than scan_clear_m_, so
    // none is within r of a HIP that moved less than that less r (0.01 voxel to spare).
    const Vec3 moved = hip - anchor_;
    const double room = scan_clear_m_ - r - 0.01 * voxel;
    update = !(room > 0) || dot(moved, moved) > room * room;
  } else if (tool_plane_count_ == 0 && !update) {
    // Free motion: one value + gradient read at the HIP. Search only when a surface may
    // be within reach (first-order distance), or the HIP entered the object.
    const FieldValue s = sample_trilinear(field, hip);
    const double e = excess(s.value);
    const double gn = norm(s.gradient);
    if (e > 0.0) update = !(excess(sample_value(field, vhip_)) > 0.0);  // starting inside: no force
    // Where the field is flat (|e| / |grad| beyond 8 voxels: a drilled cavity, uniform
    // empty value, air) the first-order distance says nothing: search there every n ticks.
    else {
      const bool flat = !(gn > 0) ? std::isfinite(s.value) : -e > 8.0 * voxel * gn;
      update = (gn > 0 && -e < (r + voxel) * gn) || (flat && ++c_ >= params_.plane_update_period);
    }
  }
  if (update) {
    ToolPlane kept[kMaxToolPlanes];
    const int kept_count = tool_plane_count_;
    std::copy(tool_planes_, tool_planes_ + kept_count, kept);
    tool_rebuild(field, hip);
    if (tool_plane_count_ == 0 && kept_count > 0 && excess(sample_value(field, hip)) > 0.0) {
      // No surface within reach of the proxy while the HIP is inside: material removed
      // around the tool (a drill), or a noisy scan. The proxy goes toward the HIP up to the
      // surface on the way (first crossing of the segment; the plane there, the centre r
      // before it); failing that, the planes of the tick before still hold the HIP.
      Vec3 q;
      scan_valid_ = false;  // these planes are not the scan's
      if (!(excess(sample_value(field, vhip_)) > 0.0) && first_crossing(field, vhip_, hip, q)) {
        const Vec3 n = outward_normal(field, q, normalized_or(vhip_ - hip, kept[0].n));
        tool_planes_[0] = {n, q};
        tool_plane_count_ = 1;
      } else {
        std::copy(kept, kept + kept_count, tool_planes_);
        tool_plane_count_ = kept_count;
      }
    }
    c_ = 0;
    solved = tool_solve(hip);  // the HIP itself without a plane
    have_solved = true;
    tool_hold_entry_side(field, hip, !reseat && !edited && was_contact_ && kept_count > 0, kept, kept_count, solved);
    if (!scan_valid_) anchor_ = solved;
    out.plane_update = true;
  }
  const Vec3 x = tool_plane_count_ == 0 ? hip : have_solved ? solved : tool_solve(hip);
  vhip_ = x;
  const Vec3 push = (x - hip) * inv_wpd_;  // device [m]
  const double depth = norm(push);
  if (!(depth > 0.0)) {
    prev_target_f_ = {};
    ramp_from_dir_ = {};
    ramp_left_s_ = 0;
    return {};
  }
  const Vec3 u = push / depth;
  Vec3 force = u * (params_.stiffness_n_per_m * depth - params_.damping_n_s_per_m * dot(v_filt_, u));
  if (dot(force, u) < 0.0) force = {};  // a wall pushes, never pulls
  bool ramped = false;
  if (params_.recovery_time_s > 0) force = ramp_force(force, out.plane_update, u, prev_target_f_, ramped);
  out.contact = true;
  out.penetration_m = norm(hip - x);
  return force;
}

}  // namespace isotouch::servo
