#version 450
// Gradient pass, four voxels of an x-row per invocation (isotouch_shared.h DensePush):
// value and world-space gradient per voxel, the same float operations in the same order
// as engine/cpu_gradient.cpp (central differences inside, one-sided at the borders), so
// the result agrees bit for bit. The neighbours are read with clamped coordinates: the
// clamped neighbour of a border voxel is the voxel itself, the CPU's `c`.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
// The volume's size as specialization constants: the index arithmetic folds (the row and
// group of an invocation are a multiply by a constant, not a per-lane division).
layout(constant_id = 0) const int NX = 1;
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
// The source's view is R32G32B32A32_SFLOAT (one fetch per quad of voxels; NX and the source
// offset multiples of 4, the host sets it only then).
layout(constant_id = 3) const bool VEC4_IN = false;
const int QX = (NX + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS;

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(push_constant) uniform Push { DensePush pc; };

float at(int i) { return texelFetch(src, i).x; }
vec4 at4(int row, ivec4 xs) {
  if (VEC4_IN) return texelFetch(src, (row + xs.x) / 4);  // xs = x0 .. x0 + 3, a whole quad
  return vec4(at(row + xs.x), at(row + xs.y), at(row + xs.z), at(row + xs.w));
}

// The derivative along an axis whose index is the same for the 4 voxels.
vec4 diff_uniform(int i, int n, vec4 lo, vec4 c, vec4 hi, float inv_2h, float inv_h) {
  if (n < 2) return vec4(0.0);
  if (i == 0) return (hi - c) * inv_h;
  if (i == n - 1) return (c - lo) * inv_h;
  return (hi - lo) * inv_2h;
}

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  if (t >= QX * NY) return;
  const int nx = NX, ny = NY, nz = NZ;
  const int y = t / QX, x0 = (t - y * QX) * ISOTOUCH_DENSE_VOXELS;
  const int zs = int(gl_GlobalInvocationID.z);  // slice within the slab
  const int z = int(pc.z0) + zs;
  const int slice = nx * ny, src0 = int(pc.src_offset) - int(pc.src_z0) * slice;
  const int row = src0 + z * slice + y * nx;
  const ivec4 xi = ivec4(x0) + ivec4(0, 1, 2, 3);
  const ivec4 xs = min(xi, ivec4(nx - 1));
  // x: the 6 voxels x0 - 1 .. x0 + 4, clamped into the row.
  float a0, a5;
  const vec4 c = at4(row, xs);
  if (VEC4_IN) {
    // The neighbouring quads, clamped into the row (at a border the voxel itself).
    const float l = texelFetch(src, (row + max(x0 - 4, 0)) / 4).w;
    const float h = texelFetch(src, (row + min(x0 + 4, nx - 4)) / 4).x;
    a0 = x0 > 0 ? l : c.x;
    a5 = x0 + 4 < nx ? h : c.w;
  } else {
    a0 = at(row + max(x0 - 1, 0));
    a5 = at(row + min(x0 + 4, nx - 1));
  }
  const vec4 xl = vec4(a0, c.xyz), xh = vec4(c.yzw, a5);
  // A lane past the row's end holds voxel nx - 1 and stores nothing; lane 3's high
  // neighbour a5 is voxel x0 + 4 only when that voxel exists.
  const vec4 yl = at4(src0 + z * slice + max(y - 1, 0) * nx, xs);
  const vec4 yh = at4(src0 + z * slice + min(y + 1, ny - 1) * nx, xs);
  const vec4 zl = at4(src0 + max(z - 1, 0) * slice + y * nx, xs);
  const vec4 zh = at4(src0 + min(z + 1, nz - 1) * slice + y * nx, xs);
  vec4 gx = (xh - xl) * pc.inv_2h_x;
  gx = mix(gx, (c - xl) * pc.inv_h_x, equal(xi, ivec4(nx - 1)));
  gx = mix(gx, (xh - c) * pc.inv_h_x, equal(xi, ivec4(0)));
  if (nx < 2) gx = vec4(0.0);
  const vec4 gy = diff_uniform(y, ny, yl, c, yh, pc.inv_2h_y, pc.inv_h_y);
  const vec4 gz = diff_uniform(z, nz, zl, c, zh, pc.inv_2h_z, pc.inv_h_z);
  const uint o = pc.dst_offset + uint((zs * ny + y) * nx + x0);
  if (x0 + 3 < nx) {
    dst[o] = vec4(c.x, gx.x, gy.x, gz.x);
    dst[o + 1u] = vec4(c.y, gx.y, gy.y, gz.y);
    dst[o + 2u] = vec4(c.z, gx.z, gy.z, gz.z);
    dst[o + 3u] = vec4(c.w, gx.w, gy.w, gz.w);
  } else {
    for (int j = 0; j < 4; ++j)
      if (x0 + j < nx) dst[o + uint(j)] = vec4(c[j], gx[j], gy[j], gz[j]);
  }
}
