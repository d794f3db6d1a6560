#version 450
// The gradient and the brick min/max (halo 1) in ONE pass over the field: one invocation per
// brick row segment of two slices - brick column bx (voxels 8 bx .. 8 bx + 7, two quads), brick
// row by, slices z = 2 zp and z + 1 - walking the rows y = 8 by - 1 .. 8 by + 8 (clamped) in order. Each row's
// quads are fetched once: the row's (min, max) over x = 8 bx - 1 .. 8 bx + 8 (clamped) feeds
// the segment's range, and the row before it gets its gradient (its y neighbours are the rows
// the walk holds; z neighbours fetched). Writes the samples of rows 8 by .. 8 by + 7 (as
// gradient_x4.comp: value, d/dx, d/dy, d/dz; the same float operations as
// engine/cpu_gradient.cpp) and the segment's (min, max) over its 10 x 10 voxels of slice z;
// minmax_slices.comp combines the segments of slices 8 bz - 1 .. 8 bz + 8 into each brick's.
//
// Min/max bit for bit as engine/cpu_filters.cpp brick_minmax_cpu: the comparison updates from
// +inf / -inf (NaN skipped), in z, y, x order; an update keeps the first of equal values
// (-0 against +0), and that rule gives the same result on any split of the sequence into
// consecutive parts reduced in order. A clamped voxel (or row) repeats one already taken
// (at the left border right before its original): never a different result.
//
// Bindings: 0 the field (R32G32B32A32_SFLOAT texel buffer: quad q of row (y, z) is texel
// (z NY + y) QX + q; NX a multiple of 4), 1 the samples (vec4 per voxel), 2 the segments
// (vec2 per (z, by, bx), bx fastest). Push: DensePush (the spacing's inverses; the whole
// volume in one binding). Dispatch: (ceil(BX BY / ISOTOUCH_DENSE_WG), 1, ceil(NZ / 2)).
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int NX = 4;
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
const int QX = NX / ISOTOUCH_DENSE_VOXELS;
const int B = int(ISOTOUCH_BRICK);
const int BX = (NX + B - 1) / B;
const int BY = (NY + B - 1) / B;

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Seg { vec2 seg[]; };
layout(push_constant) uniform Push { DensePush pc; };

// The derivative along an axis whose index is the same for the 4 voxels (gradient_x4.comp).
vec4 diff_uniform(int i, int n, vec4 lo, vec4 c, vec4 hi, float inv_2h, float inv_h) {
  if (n < 2) return vec4(0.0);
  if (i == 0) return (hi - c) * inv_h;
  if (i == n - 1) return (c - lo) * inv_h;
  return (hi - lo) * inv_2h;
}

// d/dx of the quad c of voxels xi (xl, xh: each lane's left and right neighbour, clamped).
vec4 diff_x(ivec4 xi, vec4 xl, vec4 c, vec4 xh) {
  vec4 gx = (xh - xl) * pc.inv_2h_x;
  gx = mix(gx, (c - xl) * pc.inv_h_x, equal(xi, ivec4(NX - 1)));
  gx = mix(gx, (xh - c) * pc.inv_h_x, equal(xi, ivec4(0)));
  if (NX < 2) gx = vec4(0.0);
  return gx;
}

// One row of a slice in the walk: its two quads and the edge voxels 8 bx - 1 and 8 bx + 8
// (clamped into the row).
struct Row {
  vec4 q0, q1;
  float a, h;
};

Row fetch_row(int z, int y, int bx, int q0, int q1) {
  const int row = (z * NY + y) * QX;
  Row r;
  r.q0 = texelFetch(src, row + q0);
  r.q1 = texelFetch(src, row + q1);
  const vec4 l = texelFetch(src, row + max(q0 - 1, 0)), h = texelFetch(src, row + min(q0 + 2, QX - 1));
  r.a = bx > 0 ? l.w : r.q0.x;            // voxel 8 bx - 1, clamped
  r.h = q0 + 2 <= QX - 1 ? h.x : h.w;     // voxel 8 bx + 8, clamped
  return r;
}

// The row's voxels in x order into a segment's (min, max).
vec2 take(vec2 m, Row n) {
  float mn = m.x, mx = m.y;
  mn = n.a < mn ? n.a : mn;
  mx = n.a > mx ? n.a : mx;
  [[unroll]] for (int j = 0; j < 4; ++j) {
    mn = n.q0[j] < mn ? n.q0[j] : mn;
    mx = n.q0[j] > mx ? n.q0[j] : mx;
  }
  [[unroll]] for (int j = 0; j < 4; ++j) {
    mn = n.q1[j] < mn ? n.q1[j] : mn;
    mx = n.q1[j] > mx ? n.q1[j] : mx;
  }
  mn = n.h < mn ? n.h : mn;
  mx = n.h > mx ? n.h : mx;
  return vec2(mn, mx);
}

// The samples of row y of slice z: c the row, p and n the rows y - 1 and y + 1, lo and hi
// the row in the slices z - 1 and z + 1 (all clamped).
void store_row(int z, int y, int x0, bool whole, Row p, Row c, Row n, vec4 lo0, vec4 lo1, vec4 hi0, vec4 hi1) {
  const ivec4 xi0 = ivec4(x0) + ivec4(0, 1, 2, 3), xi1 = xi0 + ivec4(4);
  const vec4 gx0 = diff_x(xi0, vec4(c.a, c.q0.xyz), c.q0, vec4(c.q0.yzw, c.q1.x));
  const vec4 gx1 = diff_x(xi1, vec4(c.q0.w, c.q1.xyz), c.q1, vec4(c.q1.yzw, c.h));
  const vec4 gy0 = diff_uniform(y, NY, p.q0, c.q0, n.q0, pc.inv_2h_y, pc.inv_h_y);
  const vec4 gy1 = diff_uniform(y, NY, p.q1, c.q1, n.q1, pc.inv_2h_y, pc.inv_h_y);
  const vec4 gz0 = diff_uniform(z, NZ, lo0, c.q0, hi0, pc.inv_2h_z, pc.inv_h_z);
  const vec4 gz1 = diff_uniform(z, NZ, lo1, c.q1, hi1, pc.inv_2h_z, pc.inv_h_z);
  const uint o = uint((z * NY + y) * NX + x0);
  dst[o] = vec4(c.q0.x, gx0.x, gy0.x, gz0.x);
  dst[o + 1u] = vec4(c.q0.y, gx0.y, gy0.y, gz0.y);
  dst[o + 2u] = vec4(c.q0.z, gx0.z, gy0.z, gz0.z);
  dst[o + 3u] = vec4(c.q0.w, gx0.w, gy0.w, gz0.w);
  if (whole) {
    dst[o + 4u] = vec4(c.q1.x, gx1.x, gy1.x, gz1.x);
    dst[o + 5u] = vec4(c.q1.y, gx1.y, gy1.y, gz1.y);
    dst[o + 6u] = vec4(c.q1.z, gx1.z, gy1.z, gz1.z);
    dst[o + 7u] = vec4(c.q1.w, gx1.w, gy1.w, gz1.w);
  }
}

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  if (t >= BX * BY) return;
  const int by = t / BX, bx = t - by * BX;
  // Slices z and z + 1 (where it exists): each one's z neighbour on the other's side is the
  // other slice's row, already in hand.
  const int z = 2 * int(gl_GlobalInvocationID.z);
  const bool two = z + 1 < NZ;
  const int zb = min(z + 1, NZ - 1), zl = max(z - 1, 0), zh = min(z + 2, NZ - 1);
  const int q0 = 2 * bx, q1 = min(2 * bx + 1, QX - 1);  // q1 = q0 where the last brick holds one quad
  const int x0 = 4 * q0;
  const bool whole = 2 * bx + 1 < QX;
  const vec2 none = vec2(uintBitsToFloat(0x7f800000u), uintBitsToFloat(0xff800000u));
  vec2 ra = none, rb = none;
  // The walk's last two rows of each slice: p (y - 1) and c (y).
  Row pa, ca, pb, cb;
  [[unroll]] for (int k = 0; k < B + 2; ++k) {
    const int yk = clamp(B * by - 1 + k, 0, NY - 1);
    const Row na = fetch_row(z, yk, bx, q0, q1), nb = fetch_row(zb, yk, bx, q0, q1);
    ra = take(ra, na);
    rb = take(rb, nb);
    // Row y = 8 by + k - 2 (k >= 2): its neighbours p (row y - 1) and n (row y + 1), clamped.
    const int y = B * by + k - 2;
    if (k >= 2 && y < NY) {
      const int rl = (zl * NY + y) * QX;
      store_row(z, y, x0, whole, pa, ca, na, texelFetch(src, rl + q0), texelFetch(src, rl + q1), cb.q0, cb.q1);
      if (two) {
        const int rh = (zh * NY + y) * QX;
        store_row(zb, y, x0, whole, pb, cb, nb, ca.q0, ca.q1, texelFetch(src, rh + q0), texelFetch(src, rh + q1));
      }
    }
    pa = ca;
    ca = na;
    pb = cb;
    cb = nb;
  }
  seg[(z * BY + by) * BX + bx] = ra;
  if (two) seg[(zb * BY + by) * BX + bx] = rb;
}
