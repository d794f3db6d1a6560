// filter_x4.glsl - one axis of a separable filter on four voxels of an x-row, shared by
// filter_x4.comp (every row of a slab) and filter_list_x4.comp (the rows of a work list).
// The axis, the radius, the mode and the volume's size are specialization constants:
// - Gaussian: dst[i] = sum_{k=-r..r} w[k + r] * src[clamp(i + k)], the normalised weights
//   (engine/cpu_filters.cpp gaussian_kernel) specialization constants too. The accumulator
//   is `precise` (no FMA contraction, no reassociation) and the taps are summed from k = -r
//   up, exactly as engine/cpu_filters.cpp does, so the result agrees bit for bit.
// - dilation (max) / erosion (min) over the box window: the running extremum starts at
//   -inf / +inf and takes a tap only if it compares greater / less, taps from k = -r up,
//   as engine/cpu_filters.cpp: NaN voxels are skipped.
// Border: clamp to edge. Bindings: 0 the source (texel buffer), 1 the destination.

layout(constant_id = 0) const int NX = 1;    // the volume's size: the index arithmetic folds
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
layout(constant_id = 3) const int AXIS = 0;  // 0 = x, 1 = y, 2 = z
layout(constant_id = 4) const int R = 0;     // taps on each side, <= ISOTOUCH_DENSE_MAX_RADIUS
layout(constant_id = 38) const uint MODE = 0u;  // 0 Gaussian, ISOTOUCH_MORPH_MAX, ISOTOUCH_MORPH_MIN
// The source's view is R32G32B32A32_SFLOAT: texel q is the quad of voxels 4 q .. 4 q + 3, one
// fetch per quad instead of four (rows start on a quad: NX and the source offset multiples
// of 4; the host sets it only then).
layout(constant_id = 39) const bool VEC4_IN = false;
const int QX = (NX + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS;

layout(constant_id = 5) const float W0 = 0.0;
layout(constant_id = 6) const float W1 = 0.0;
layout(constant_id = 7) const float W2 = 0.0;
layout(constant_id = 8) const float W3 = 0.0;
layout(constant_id = 9) const float W4 = 0.0;
layout(constant_id = 10) const float W5 = 0.0;
layout(constant_id = 11) const float W6 = 0.0;
layout(constant_id = 12) const float W7 = 0.0;
layout(constant_id = 13) const float W8 = 0.0;
layout(constant_id = 14) const float W9 = 0.0;
layout(constant_id = 15) const float W10 = 0.0;
layout(constant_id = 16) const float W11 = 0.0;
layout(constant_id = 17) const float W12 = 0.0;
layout(constant_id = 18) const float W13 = 0.0;
layout(constant_id = 19) const float W14 = 0.0;
layout(constant_id = 20) const float W15 = 0.0;
layout(constant_id = 21) const float W16 = 0.0;
layout(constant_id = 22) const float W17 = 0.0;
layout(constant_id = 23) const float W18 = 0.0;
layout(constant_id = 24) const float W19 = 0.0;
layout(constant_id = 25) const float W20 = 0.0;
layout(constant_id = 26) const float W21 = 0.0;
layout(constant_id = 27) const float W22 = 0.0;
layout(constant_id = 28) const float W23 = 0.0;
layout(constant_id = 29) const float W24 = 0.0;
layout(constant_id = 30) const float W25 = 0.0;
layout(constant_id = 31) const float W26 = 0.0;
layout(constant_id = 32) const float W27 = 0.0;
layout(constant_id = 33) const float W28 = 0.0;
layout(constant_id = 34) const float W29 = 0.0;
layout(constant_id = 35) const float W30 = 0.0;
layout(constant_id = 36) const float W31 = 0.0;
layout(constant_id = 37) const float W32 = 0.0;
// Weight k of the kernel: a switch on the (unrolled, constant) tap index folds to the constant.
float W_at(int k) {
  switch (k) {
    case 0: return W0;
    case 1: return W1;
    case 2: return W2;
    case 3: return W3;
    case 4: return W4;
    case 5: return W5;
    case 6: return W6;
    case 7: return W7;
    case 8: return W8;
    case 9: return W9;
    case 10: return W10;
    case 11: return W11;
    case 12: return W12;
    case 13: return W13;
    case 14: return W14;
    case 15: return W15;
    case 16: return W16;
    case 17: return W17;
    case 18: return W18;
    case 19: return W19;
    case 20: return W20;
    case 21: return W21;
    case 22: return W22;
    case 23: return W23;
    case 24: return W24;
    case 25: return W25;
    case 26: return W26;
    case 27: return W27;
    case 28: return W28;
    case 29: return W29;
    case 30: return W30;
    case 31: return W31;
    case 32: return W32;
  }
  return 0.0;
}

// One tap into the accumulator: weighted sum, or the comparison update of max / min.
vec4 tap(vec4 acc, int k, vec4 v) {
  if (MODE == ISOTOUCH_MORPH_MAX) return mix(acc, v, greaterThan(v, acc));
  if (MODE == ISOTOUCH_MORPH_MIN) return mix(acc, v, lessThan(v, acc));
  precise vec4 term = W_at(k) * v;
  precise vec4 sum = acc + term;
  return sum;
}

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { float dst[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst4 { vec4 dst4[]; };

float at(int i) { return texelFetch(src, i).x; }
// The quad whose first voxel is element i (i a multiple of 4) of a VEC4_IN source.
vec4 quad_at(int i) { return texelFetch(src, i / 4); }

// Voxel x0 - R + j of the row at element `row` (VEC4_IN), clamped into the row: the quads
// x0 / 4 - QN .. x0 / 4 + QN fetched once each; a quad outside the row stands for voxel 0
// or nx - 1 in every lane (rows hold whole quads: the clamped quad's first or last lane).
const int QN = (R + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS;

// The filtered value of voxels x0 .. x0 + 3 of row (y, z) (lanes past the row's end hold
// voxel nx - 1); src0: the texel of voxel (0, 0, 0) in the source binding.
vec4 filter_quad(int x0, int y, int z, int src0) {
  const int nx = NX, ny = NY, nz = NZ;
  const int slice = nx * ny;
  const ivec4 xs = min(ivec4(x0) + ivec4(0, 1, 2, 3), ivec4(nx - 1));
  precise vec4 acc = vec4(MODE == ISOTOUCH_MORPH_MAX ? uintBitsToFloat(0xff800000u)
                          : MODE == ISOTOUCH_MORPH_MIN ? uintBitsToFloat(0x7f800000u) : 0.0);
  if (AXIS == 0 && VEC4_IN) {
    // The quads around x0 (2 QN + 1 fetches), the window read from them.
    const int row = src0 + z * slice + y * nx, q = x0 / 4;
    float win[4 * (2 * ((ISOTOUCH_DENSE_MAX_RADIUS + 3) / 4) + 1)];
    for (int j = 0; j <= 2 * QN; ++j) {
      const int qj = q + j - QN;
      vec4 v = quad_at(row + 4 * clamp(qj, 0, QX - 1));
      if (qj < 0) v = vec4(v.x);
      if (qj > QX - 1) v = vec4(v.w);
      win[4 * j] = v.x;
      win[4 * j + 1] = v.y;
      win[4 * j + 2] = v.z;
      win[4 * j + 3] = v.w;
    }
    const int s = 4 * QN - R;  // window element of voxel x0 - R
    for (int k = 0; k <= 2 * R; ++k) {
      acc = tap(acc, k, vec4(win[s + k], win[s + k + 1], win[s + k + 2], win[s + k + 3]));
    }
  } else if (AXIS == 0) {
    // The window x0 - r .. x0 + 3 + r, clamped into the row, read once.
    const int row = src0 + z * slice + y * nx;
    float win[ISOTOUCH_DENSE_VOXELS + 2 * ISOTOUCH_DENSE_MAX_RADIUS];
    for (int j = 0; j < 4 + 2 * R; ++j) win[j] = at(row + clamp(x0 - R + j, 0, nx - 1));
    for (int k = 0; k <= 2 * R; ++k) {
      acc = tap(acc, k, vec4(win[k], win[k + 1], win[k + 2], win[k + 3]));
    }
  } else if (VEC4_IN) {
    const int n = AXIS == 1 ? ny : nz, i = AXIS == 1 ? y : z;
    const int stride = AXIS == 1 ? nx : slice;
    const int row = AXIS == 1 ? src0 + z * slice : src0 + y * nx;
    for (int k = 0; k <= 2 * R; ++k) {
      acc = tap(acc, k, quad_at(row + clamp(i + k - R, 0, n - 1) * stride + x0));
    }
  } else {
    // Voxel j along the axis is row + j * stride (+ the lane's x).
    const int n = AXIS == 1 ? ny : nz, i = AXIS == 1 ? y : z;
    const int stride = AXIS == 1 ? nx : slice;
    const int row = AXIS == 1 ? src0 + z * slice : src0 + y * nx;
    for (int k = 0; k <= 2 * R; ++k) {
      const int p = row + clamp(i + k - R, 0, n - 1) * stride;
      acc = tap(acc, k, vec4(at(p + xs.x), at(p + xs.y), at(p + xs.z), at(p + xs.w)));
    }
  }
  return acc;
}

// Stores the voxels of a quad that lie in the row at element o of dst (one vec4 store when
// `aligned`: o a multiple of 4 and the quad whole).
void store_quad(uint o, int x0, vec4 acc, bool aligned) {
  if (aligned && x0 + 3 < NX) {
    dst4[o / 4u] = acc;
  } else {
    for (int j = 0; j < 4; ++j)
      if (x0 + j < NX) dst[o + uint(j)] = acc[j];
  }
}
