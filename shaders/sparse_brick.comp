#version 450
// Sparse chain, one workgroup per candidate 8^3 brick (layout: shaders/isotouch_shared.h,
// "sparse chain"). Local position l <-> voxel g0 + l,
// g0 = 8 b - 1 - R; only positions inside the volume are computed (and ever read).
// Stages, separated by barriers:
//  1.-2. every 1-D filter op (Gaussian x/y/z, box max/min) on the box of the region its
//     successors need, taps clamped to the volume exactly as the dense passes clamp
//     (gaussian1d.comp, morph1d.comp: same operations, same order, `precise`); the first
//     op reads the raw voxels from the src binding, the others shared memory (with no
//     filter the raw region is copied into shared memory);
//  3. (min, max) of the smoothed brick widened by 1 voxel (clamped to the volume), NaN
//     skipped, -0 folded into +0 so that the result does not depend on the reduction order;
//  4. if that range straddles tau: value + gradient (gradient.comp's rule, one-sided at the
//     volume border) at the 9^3 stored samples, background and 0 beyond the grid.
// Bit-identical with the dense CPU chain (run_chain_cpu) at every stored voxel.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"
#extension GL_KHR_shader_subgroup_basic : require

// The workgroup is one subgroup (ISOTOUCH_SPARSE_WG <= subgroupSize, checked by the host),
// so a subgroup barrier with shared-memory ordering synchronises the whole workgroup. On
// lavapipe it costs nothing, where barrier() switches coroutines.
void wg_barrier() {
  subgroupMemoryBarrierShared();
  subgroupBarrier();
}

layout(local_size_x = ISOTOUCH_SPARSE_WG) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) readonly buffer Cand { uint cand[]; };
layout(std430, set = 0, binding = 2) readonly buffer Params { uint params[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Ranges { vec4 ranges[]; };  // lo, hi, NaN seen, active
layout(std430, set = 0, binding = 4) writeonly buffer Pool { vec4 pool[]; };
layout(push_constant) uniform Push { SparseBrickPush pc; };

shared float fbuf[ISOTOUCH_SPARSE_SHARED_FLOATS];
shared float red_lo[ISOTOUCH_SPARSE_WG];
shared float red_hi[ISOTOUCH_SPARSE_WG];
shared uint s_nan;

// t / d for t < 16384, d <= 64 without an integer division (lavapipe scalarises those):
// (t + 0.5) / d is at least 0.5 / d from an integer, far more than the float error.
uint udiv(uint t, uint d) { return uint((float(t) + 0.5) / float(d)); }

// Decodes item t of a box of width w (x fastest) into its offset from the box corner.
ivec3 decode(uint t, ivec3 w) {
  uint q = udiv(t, uint(w.x));
  uint z = udiv(q, uint(w.y));
  return ivec3(int(t - q * uint(w.x)), int(q - z * uint(w.y)), int(z));
}

// Offset of local position l in a buffer holding the box [lo, lo + w) (x fastest).
int at(ivec3 l, ivec3 lo, ivec3 w) { return ((l.z - lo.z) * w.y + (l.y - lo.y)) * w.x + (l.x - lo.x); }

float diff(int i, int n, float lo, float c, float hi, float inv_2h, float inv_h) {
  if (n < 2) return 0.0;
  if (i == 0) return (hi - c) * inv_h;
  if (i == n - 1) return (c - lo) * inv_h;
  return (hi - lo) * inv_2h;
}

void samples(const uint ci, const ivec3 b8, const ivec3 g0, const ivec3 n, const int fb, const ivec3 clo,
             const ivec3 cw);

// Candidate ci (index into cand[]): stages 1-4 of the file comment.
void brick(const uint ci) {
  const uint lid = gl_LocalInvocationID.x;
  const uint id = cand[ci];
  const uint bxy = pc.bx * pc.by;
  const uint bz = id / bxy;
  const uint by = (id - bz * bxy) / pc.bx;
  const uint bx = id - bz * bxy - by * pc.bx;
  const ivec3 b8 = ivec3(bx, by, bz) * 8;
  const ivec3 S = ivec3(pc.sx, pc.sy, pc.sz);
  const ivec3 R = ivec3(pc.rx, pc.ry, pc.rz);
  const ivec3 n = ivec3(pc.nx, pc.ny, pc.nz);
  const ivec3 g0 = b8 - 1 - R;               // voxel of local position 0
  const ivec3 vlo = max(-g0, ivec3(0));      // local range inside the volume
  const ivec3 vhi = min(S - 1, n - 1 - g0);
  // Raw voxel of local position l: src[gbase + l.z * gsz + l.y * nx + l.x].
  const int gsz = int(pc.nx * pc.ny);
  const int gbase = int(pc.src_offset) + (g0.z - int(pc.src_z0)) * gsz + g0.y * int(pc.nx) + g0.x;
  if (lid == 0u) s_nan = 0u;

  // The box the current field is stored on, and where (A = 0, B = buf_b).
  ivec3 clo = vlo, cw = vhi - vlo + 1;
  uint cbase = 0u;
  if (pc.n_ops == 0u) {  // no filter: the raw region is the field
    const uint count = uint(cw.x * cw.y * cw.z);
    for (uint t = lid; t < count; t += ISOTOUCH_SPARSE_WG) {
      const ivec3 l = clo + decode(t, cw);
      fbuf[at(l, clo, cw)] = src[gbase + l.z * gsz + l.y * int(pc.nx) + l.x];
    }
  }
  wg_barrier();

  // Filter ops; m = radius consumed so far per axis (valid band [m, S - 1 - m]). No
  // dynamic indexing of vector components (lavapipe spills those to memory per lane).
  ivec3 m = ivec3(0);
  for (uint o = 0u; o < pc.n_ops; ++o) {
    const int axis = int(params[4u * o]);
    const int r = int(params[4u * o + 1u]);
    const uint kind = params[4u * o + 2u];
    const uint woff = 4u * ISOTOUCH_SPARSE_MAX_OPS + params[4u * o + 3u];
    const ivec3 e = ivec3(axis == 0 ? r : 0, axis == 1 ? r : 0, axis == 2 ? r : 0);
    const ivec3 lo = max(m + e, vlo), hi = min(S - 1 - m - e, vhi);
    const ivec3 w = hi - lo + 1;
    const uint count = uint(w.x * w.y * w.z);
    const int ilo = axis == 0 ? vlo.x : (axis == 1 ? vlo.y : vlo.z);
    const int ihi = axis == 0 ? vhi.x : (axis == 1 ? vhi.y : vhi.z);
    const int dbase = (o & 1u) == 0u ? 0 : int(pc.buf_b);
    const bool gauss = kind == ISOTOUCH_SPARSE_OP_GAUSS, is_max = kind == ISOTOUCH_SPARSE_OP_MAX;
    if (o == 0u) {  // the first op reads the raw voxels
      const int stride = axis == 0 ? 1 : (axis == 1 ? int(pc.nx) : gsz);
      for (uint t = lid; t < count; t += ISOTOUCH_SPARSE_WG) {
        const ivec3 l = lo + decode(t, w);
        const int i = axis == 0 ? l.x : (axis == 1 ? l.y : l.z);
        const int line = gbase + l.z * gsz + l.y * int(pc.nx) + l.x - i * stride;  // tap j at line + j * stride
        float result;
        if (gauss) {
          precise float acc = 0.0;
          for (int k = -r; k <= r; ++k) {
            const float v = src[line + clamp(i + k, ilo, ihi) * stride];
            precise float term = uintBitsToFloat(params[woff + uint(k + r)]) * v;
            acc = acc + term;
          }
          result = acc;
        } else {
          float mm = is_max ? uintBitsToFloat(0xff800000u) : uintBitsToFloat(0x7f800000u);
          for (int k = -r; k <= r; ++k) {
            const float v = src[line + clamp(i + k, ilo, ihi) * stride];
            mm = is_max ? (v > mm ? v : mm) : (v < mm ? v : mm);
          }
          result = mm;
        }
        fbuf[dbase + at(l, lo, w)] = result;
      }
    } else {
      const int stride = axis == 0 ? 1 : (axis == 1 ? cw.x : cw.x * cw.y);
      for (uint t = lid; t < count; t += ISOTOUCH_SPARSE_WG) {
        const ivec3 l = lo + decode(t, w);
        const int i = axis == 0 ? l.x : (axis == 1 ? l.y : l.z);
        const int line = int(cbase) + at(l, clo, cw) - i * stride;  // tap j at line + j * stride
        float result;
        if (gauss) {
          precise float acc = 0.0;
          for (int k = -r; k <= r; ++k) {
            const float v = fbuf[line + clamp(i + k, ilo, ihi) * stride];
            precise float term = uintBitsToFloat(params[woff + uint(k + r)]) * v;
            acc = acc + term;
          }
          result = acc;
        } else {
          float mm = is_max ? uintBitsToFloat(0xff800000u) : uintBitsToFloat(0x7f800000u);
          for (int k = -r; k <= r; ++k) {
            const float v = fbuf[line + clamp(i + k, ilo, ihi) * stride];
            mm = is_max ? (v > mm ? v : mm) : (v < mm ? v : mm);
          }
          result = mm;
        }
        fbuf[dbase + at(l, lo, w)] = result;
      }
    }
    m += e;
    clo = lo;
    cw = w;
    cbase = uint(dbase);
    wg_barrier();
  }
  const int fb = int(cbase);

  // 3. Range of the smoothed brick widened by 1 voxel: local [R, R + 9] in the volume.
  {
    const ivec3 lo = max(R, vlo), hi = min(R + 9, vhi);
    const ivec3 w = hi - lo + 1;
    const uint count = uint(w.x * w.y * w.z);
    float mn = uintBitsToFloat(0x7f800000u), mx = uintBitsToFloat(0xff800000u);
    bool nan = false;
    for (uint t = lid; t < count; t += ISOTOUCH_SPARSE_WG) {
      const ivec3 l = lo + decode(t, w);
      const float v = fbuf[fb + at(l, clo, cw)];
      nan = nan || isnan(v);
      mn = v < mn ? v : mn;
      mx = v > mx ? v : mx;
    }
    if (nan) atomicOr(s_nan, 1u);
    precise float mn0 = mn + 0.0;  // -0 -> +0
    precise float mx0 = mx + 0.0;
    red_lo[lid] = mn0;
    red_hi[lid] = mx0;
  }
  wg_barrier();
  for (uint s = ISOTOUCH_SPARSE_WG / 2u; s > 0u; s >>= 1u) {
    if (lid < s) {
      const float a = red_lo[lid + s], b = red_hi[lid + s];
      red_lo[lid] = a < red_lo[lid] ? a : red_lo[lid];
      red_hi[lid] = b > red_hi[lid] ? b : red_hi[lid];
    }
    wg_barrier();
  }
  const float lo_v = red_lo[0], hi_v = red_hi[0];
  const bool has_nan = s_nan != 0u;
  // core::tile_value + bricked_input_from_dense's rule: uniform if entirely outside, or
  // entirely inside with no NaN voxel (a NaN voxel is outside and must keep reading NaN).
  const bool above = pc.inside_above != 0u;
  const bool inside_u = above ? lo_v > pc.threshold : hi_v < pc.threshold;
  const bool outside_u = above ? hi_v <= pc.threshold : lo_v >= pc.threshold;
  const bool is_active = !(lo_v > hi_v || outside_u || (inside_u && !has_nan));
  if (lid == 0u) ranges[ci] = vec4(lo_v, hi_v, has_nan ? 1.0 : 0.0, is_active ? 1.0 : 0.0);
  if (is_active) samples(ci, b8, g0, n, fb, clo, cw);  // workgroup-uniform branch
}

// 4. The 9^3 samples of an active brick into its pool slot.
void samples(const uint ci, const ivec3 b8, const ivec3 g0, const ivec3 n, const int fb, const ivec3 clo,
             const ivec3 cw) {
  const uint lid = gl_LocalInvocationID.x;

  const uint slot = (ci - pc.pool_base) * ISOTOUCH_SPARSE_SAMPLES;
  for (uint t = lid; t < ISOTOUCH_SPARSE_SAMPLES; t += ISOTOUCH_SPARSE_WG) {
    const uint k = t / 81u, j = (t - k * 81u) / 9u, i = t - k * 81u - j * 9u;
    const ivec3 gq = b8 + ivec3(i, j, k);
    vec4 s;
    if (gq.x >= n.x || gq.y >= n.y || gq.z >= n.z) {
      s = vec4(pc.background, 0.0, 0.0, 0.0);
    } else {
      const int p = fb + at(gq - g0, clo, cw);
      const int sy = cw.x, sz = cw.x * cw.y;
      const float c = fbuf[p];
      const float xl = gq.x > 0 ? fbuf[p - 1] : c, xh = gq.x + 1 < n.x ? fbuf[p + 1] : c;
      const float yl = gq.y > 0 ? fbuf[p - sy] : c, yh = gq.y + 1 < n.y ? fbuf[p + sy] : c;
      const float zl = gq.z > 0 ? fbuf[p - sz] : c, zh = gq.z + 1 < n.z ? fbuf[p + sz] : c;
      s = vec4(c, diff(gq.x, n.x, xl, c, xh, pc.inv_2h_x, pc.inv_h_x),
               diff(gq.y, n.y, yl, c, yh, pc.inv_2h_y, pc.inv_h_y),
               diff(gq.z, n.z, zl, c, zh, pc.inv_2h_z, pc.inv_h_z));
    }
    pool[slot + t] = s;
  }
}

// Each workgroup takes candidates cand_offset + g, + g + G, ... below cand_end (G workgroups):
// lavapipe pays a fixed cost per workgroup, far more than a barrier within one. llvmpipe
// stops EVERY loop of an invocation, silently, once 65535 loop trips have run in total
// (one counter for all loops): the host keeps the bricks per workgroup under that budget
// (sparse::loop_trips_per_brick mirrors the loops below; keep them in step).
void main() {
  for (uint ci = pc.cand_offset + gl_WorkGroupID.x; ci < pc.cand_end; ci += pc.groups) {
    brick(ci);
    // llvmpipe's loop budget: once spent, every loop runs one trip (and stays so), so a
    // loop of n_ops + 2 trips that ran fewer says this brick may be cut short: flag it
    // (ranges[ci].w = 2, the host throws rather than publish it).
    uint trips = 0u;
    for (uint i = 0u; i < pc.n_ops + 2u; ++i) ++trips;
    if (trips != pc.n_ops + 2u && gl_LocalInvocationID.x == 0u) ranges[ci].w = 2.0;
    wg_barrier();  // the next brick reuses the shared buffers
  }
}
