#version 450
// The sparse chain's Gaussian in ONE pass (x, y and z fused), on a work list of columns:
// each invocation walks one column of output quads (x-quad q, slice z, rows y0 .. y0 + n - 1)
// and keeps the x-filtered quads of the rows it still needs in registers, so every source
// quad is fetched once per column step and every output is stored once - no intermediate
// fields, no second or third pass over the candidates' extents.
//
// The float operations are those of the three separate passes (filter_x4.glsl,
// engine/cpu_filters.cpp) in the same order: the x pass's value of row (y', z') is
// sum_k wx[k] * src[clamp(x + k - RX)] from k = 0 up, the y pass's sum_k wy[k] * X(clamp(y + k
// - RY), z'), the z pass's sum_k wz[k] * Y(y, clamp(z + k - RZ)); each product and sum
// `precise` (no contraction, no reassociation): the result agrees bit for bit.
//
// Bindings: 0 the source voxels (R32G32B32A32_SFLOAT texel buffer: quad q of row (y, z) is
// texel (z NY + y) QX + q; NX a multiple of 4), 1 the destination field (vec4 = one quad,
// dense-addressed), 2 the work list (R32_SFLOAT texels, two per unit: q + QX z (PAIRS:
// 2 (q + QX z) + pair) and y0 * ISOTOUCH_LIST_PACK + n, integers below 2^24). One
// invocation per unit.
//
// Every loop with a constant trip count (radii are specialization constants) carries
// [[unroll]]: unrolled, the rings are registers; left to the driver, llvmpipe kept the
// paired shader's loops and arrays and took twice the CPU time.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(push_constant) uniform Push { ListPush pc; };

layout(constant_id = 0) const int NX = 4;
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
layout(constant_id = 3) const int RX = 0;  // radii, each <= ISOTOUCH_FUSED_MAX_RADIUS
layout(constant_id = 4) const int RY = 0;
layout(constant_id = 5) const int RZ = 0;
// Weights k = 0 .. 2 R of each axis (ISOTOUCH_FUSED_MAX_RADIUS = 4: 9 a side).
layout(constant_id = 6) const float WX0 = 0.0;
layout(constant_id = 7) const float WX1 = 0.0;
layout(constant_id = 8) const float WX2 = 0.0;
layout(constant_id = 9) const float WX3 = 0.0;
layout(constant_id = 10) const float WX4 = 0.0;
layout(constant_id = 11) const float WX5 = 0.0;
layout(constant_id = 12) const float WX6 = 0.0;
layout(constant_id = 13) const float WX7 = 0.0;
layout(constant_id = 14) const float WX8 = 0.0;
layout(constant_id = 15) const float WY0 = 0.0;
layout(constant_id = 16) const float WY1 = 0.0;
layout(constant_id = 17) const float WY2 = 0.0;
layout(constant_id = 18) const float WY3 = 0.0;
layout(constant_id = 19) const float WY4 = 0.0;
layout(constant_id = 20) const float WY5 = 0.0;
layout(constant_id = 21) const float WY6 = 0.0;
layout(constant_id = 22) const float WY7 = 0.0;
layout(constant_id = 23) const float WY8 = 0.0;
layout(constant_id = 24) const float WZ0 = 0.0;
layout(constant_id = 25) const float WZ1 = 0.0;
layout(constant_id = 26) const float WZ2 = 0.0;
layout(constant_id = 27) const float WZ3 = 0.0;
layout(constant_id = 28) const float WZ4 = 0.0;
layout(constant_id = 29) const float WZ5 = 0.0;
layout(constant_id = 30) const float WZ6 = 0.0;
layout(constant_id = 31) const float WZ7 = 0.0;
layout(constant_id = 32) const float WZ8 = 0.0;
// The work list pairs slices (engine/sparse_lists.cpp make_column_list with pairs): a unit's
// first texel is 2 (q + QX z) + pair, pair 1 meaning slices z and z + 1.
layout(constant_id = 33) const bool PAIRS = false;
const int QX = NX / ISOTOUCH_DENSE_VOXELS;
const int M = ISOTOUCH_FUSED_MAX_RADIUS;

// The switches on (unrolled, constant) tap indices fold to the constants.
float wx(int k) {
  switch (k) {
    case 0: return WX0;
    case 1: return WX1;
    case 2: return WX2;
    case 3: return WX3;
    case 4: return WX4;
    case 5: return WX5;
    case 6: return WX6;
    case 7: return WX7;
    case 8: return WX8;
  }
  return 0.0;
}
float wy(int k) {
  switch (k) {
    case 0: return WY0;
    case 1: return WY1;
    case 2: return WY2;
    case 3: return WY3;
    case 4: return WY4;
    case 5: return WY5;
    case 6: return WY6;
    case 7: return WY7;
    case 8: return WY8;
  }
  return 0.0;
}
float wz(int k) {
  switch (k) {
    case 0: return WZ0;
    case 1: return WZ1;
    case 2: return WZ2;
    case 3: return WZ3;
    case 4: return WZ4;
    case 5: return WZ5;
    case 6: return WZ6;
    case 7: return WZ7;
    case 8: return WZ8;
  }
  return 0.0;
}

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(set = 0, binding = 2) uniform samplerBuffer work;

vec4 weighted(vec4 acc, float w, vec4 v) {
  precise vec4 term = w * v;
  precise vec4 sum = acc + term;
  return sum;
}

// The x pass's quad q of row (y, z) (both already clamped): quads q - 1 .. q + 1 (clamped;
// outside the row a quad stands for voxel 0 or NX - 1 in every lane), taps k = 0 .. 2 RX.
vec4 x_quad(int q, int y, int z) {
  const int row = (z * NY + y) * QX;
  float win[12];
  [[unroll]] for (int j = 0; j < 3; ++j) {
    const int qj = q + j - 1;
    vec4 v = texelFetch(src, row + clamp(qj, 0, QX - 1));
    if (qj < 0) v = vec4(v.x);
    if (qj > QX - 1) v = vec4(v.w);
    win[4 * j] = v.x;
    win[4 * j + 1] = v.y;
    win[4 * j + 2] = v.z;
    win[4 * j + 3] = v.w;
  }
  precise vec4 acc = vec4(0.0);
  [[unroll]] for (int k = 0; k <= 2 * RX; ++k) {
    const int s = 4 - RX + k;  // window element of voxel 4 q - RX + k
    acc = weighted(acc, wx(k), vec4(win[s], win[s + 1], win[s + 2], win[s + 3]));
  }
  return acc;
}

// One column of slice z (PAIRS false: the list names single slices).
void column(int q, int z, int y0, int n) {
  // ring[kz][ky]: the x pass at row y - RY + ky of slice clamp(z - RZ + kz), rows clamped.
  vec4 ring[2 * M + 1][2 * M + 1];
  [[unroll]] for (int kz = 0; kz <= 2 * RZ; ++kz) {
    const int zz = clamp(z - RZ + kz, 0, NZ - 1);
    [[unroll]] for (int ky = 1; ky <= 2 * RY; ++ky) ring[kz][ky] = x_quad(q, clamp(y0 - 1 - RY + ky, 0, NY - 1), zz);
  }
  for (int s = 0; s < n; ++s) {
    const int y = y0 + s;
    precise vec4 acc = vec4(0.0);
    [[unroll]] for (int kz = 0; kz <= 2 * RZ; ++kz) {
      [[unroll]] for (int ky = 0; ky < 2 * RY; ++ky) ring[kz][ky] = ring[kz][ky + 1];
      ring[kz][2 * RY] = x_quad(q, min(y + RY, NY - 1), clamp(z - RZ + kz, 0, NZ - 1));
      precise vec4 yacc = vec4(0.0);
      [[unroll]] for (int ky = 0; ky <= 2 * RY; ++ky) yacc = weighted(yacc, wy(ky), ring[kz][ky]);
      acc = weighted(acc, wz(kz), yacc);
    }
    dst[(z * NY + y) * QX + q] = acc;
  }
}

// The columns of slices z and z + 1 at once (PAIRS true, `pair`; otherwise slice z alone):
// the x and y passes of their 2 RZ common slices computed once. A single unit's output
// z + 1 is computed and not stored (every lane runs the same code).
void column_pair(int q, int z, int y0, int n, bool pair) {
  // ring[kz][ky]: the x pass at row y - RY + ky of slice clamp(z - RZ + kz), rows clamped;
  // slices z - RZ .. z + 1 + RZ.
  vec4 ring[2 * M + 2][2 * M + 1];
  [[unroll]] for (int kz = 0; kz <= 2 * RZ + 1; ++kz) {
    const int zz = clamp(z - RZ + kz, 0, NZ - 1);
    [[unroll]] for (int ky = 1; ky <= 2 * RY; ++ky) ring[kz][ky] = x_quad(q, clamp(y0 - 1 - RY + ky, 0, NY - 1), zz);
  }
  for (int s = 0; s < n; ++s) {
    const int y = y0 + s;
    vec4 yacc[2 * M + 2];  // the y pass of row y in each ring slice
    [[unroll]] for (int kz = 0; kz <= 2 * RZ + 1; ++kz) {
      [[unroll]] for (int ky = 0; ky < 2 * RY; ++ky) ring[kz][ky] = ring[kz][ky + 1];
      ring[kz][2 * RY] = x_quad(q, min(y + RY, NY - 1), clamp(z - RZ + kz, 0, NZ - 1));
      precise vec4 ya = vec4(0.0);
      [[unroll]] for (int ky = 0; ky <= 2 * RY; ++ky) ya = weighted(ya, wy(ky), ring[kz][ky]);
      yacc[kz] = ya;
    }
    precise vec4 acc = vec4(0.0), acc1 = vec4(0.0);
    [[unroll]] for (int kz = 0; kz <= 2 * RZ; ++kz) {
      acc = weighted(acc, wz(kz), yacc[kz]);
      acc1 = weighted(acc1, wz(kz), yacc[kz + 1]);
    }
    dst[(z * NY + y) * QX + q] = acc;
    if (pair) dst[((z + 1) * NY + y) * QX + q] = acc1;
  }
}

void main() {
  const uint u = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * pc.groups_x * uint(ISOTOUCH_DENSE_WG);
  if (u >= pc.units) return;
  const int i = 2 * int(pc.unit0 + u);
  const int a2 = int(texelFetch(work, i).x);
  const int packed = int(texelFetch(work, i + 1).x);
  const int a = PAIRS ? a2 >> 1 : a2;
  const int z = a / QX, q = a - z * QX;
  const int y0 = packed / int(ISOTOUCH_LIST_PACK), n = packed % int(ISOTOUCH_LIST_PACK);
  if (PAIRS)
    column_pair(q, z, y0, n, (a2 & 1) != 0);
  else
    column(q, z, y0, n);
}
