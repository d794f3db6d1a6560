#version 450
// Brick min/max (halo 1), first step over the whole field: one invocation per brick row
// segment of one slice - brick column bx (voxels 8 bx - 1 .. 8 bx + 8, clamped), brick row by
// (rows 8 by - 1 .. 8 by + 8, clamped), slice z - reducing its 10 x 10 voxels in y, x order
// into (min, max); minmax_slices.comp combines the segments of slices 8 bz - 1 .. 8 bz + 8
// into each brick's. Each row: its two quads (one fetch each, RGBA32F view) and the voxels
// either side (one float fetch each, R32F view of the same buffer).
//
// Bit for bit engine/cpu_filters.cpp brick_minmax_cpu: comparison updates from +inf / -inf
// (NaN skipped) in z, y, x order; an update keeps the first of equal values (-0 against +0),
// and that rule gives the same result on any split of the sequence into consecutive parts
// reduced in order. A clamped voxel or row repeats one already taken (at the left border
// right before its original): never a different result.
//
// Bindings: 0 the field (RGBA32F texel buffer: quad q of row (y, z) is texel (z NY + y) QX
// + q; NX a multiple of 4), 1 the segments (vec2 per (z, by, bx), bx fastest), 2 the field
// again (R32F texel buffer). Dispatch: (ceil(BX BY / ISOTOUCH_DENSE_WG), 1, NZ).
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

layout(set = 0, binding = 0) uniform samplerBuffer quads;
layout(std430, set = 0, binding = 1) writeonly buffer Seg { vec2 seg[]; };
layout(set = 0, binding = 2) uniform samplerBuffer floats;

vec2 take(vec2 m, float v) { return vec2(v < m.x ? v : m.x, v > m.y ? v : m.y); }

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  if (t >= BX * BY) return;
  const int by = t / BX, bx = t - by * BX;
  const int z = int(gl_GlobalInvocationID.z);
  const int q0 = 2 * bx, q1 = min(2 * bx + 1, QX - 1);  // q1 = q0 where the last brick holds one quad
  const bool whole = 2 * bx + 1 < QX;
  const int xa = max(B * bx - 1, 0), xh = min(B * bx + B, NX - 1);  // the voxels either side, clamped
  vec2 m = vec2(uintBitsToFloat(0x7f800000u), uintBitsToFloat(0xff800000u));
  [[unroll]] for (int k = 0; k < B + 2; ++k) {
    const int row = (z * NY + clamp(B * by - 1 + k, 0, NY - 1)) * QX;
    const vec4 a = texelFetch(quads, row + q0);
    m = take(m, texelFetch(floats, 4 * row + xa).x);
    [[unroll]] for (int j = 0; j < 4; ++j) m = take(m, a[j]);
    if (whole) {
      const vec4 b = texelFetch(quads, row + q1);
      [[unroll]] for (int j = 0; j < 4; ++j) m = take(m, b[j]);
    }
    m = take(m, texelFetch(floats, 4 * row + xh).x);
  }
  seg[(z * BY + by) * BX + bx] = m;
}
