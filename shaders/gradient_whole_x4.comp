#version 450
// The gradient over the whole field (engine/gradient_pass.cpp, where the field is one binding
// and one texel view, rows hold whole quads of at least 8 voxels and ny, nz >= 2; else
// gradient_x4.comp by z-slab), the fastest form the lavapipe study measured: four voxels of an
// x-row per invocation, the field read through two texel-buffer views of one buffer (binding 0
// as RGBA32F quads: the quad and its y and z neighbours; binding 2 as R32F: the one voxel on
// each side in x), four vec4 sample stores, 64x1x1 workgroups over a (ceil(QX / 64), NY, NZ)
// grid, the size and the inverse spacings specialization constants.
// Per voxel (value, d/dx, d/dy, d/dz): central differences inside, one-sided at the borders,
// the float operations of engine/cpu_gradient.cpp (bit for bit). Bindings: 0 the field (vec4
// view), 1 the samples, 2 the field (float view).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int NX = 8;
layout(constant_id = 1) const int NY = 2;
layout(constant_id = 2) const int NZ = 2;
layout(constant_id = 3) const float I2HX = 1.0;  // 1 / (2 spacing) [1/m]
layout(constant_id = 4) const float I2HY = 1.0;
layout(constant_id = 5) const float I2HZ = 1.0;
layout(constant_id = 6) const float IHX = 1.0;   // 1 / spacing [1/m]
layout(constant_id = 7) const float IHY = 1.0;
layout(constant_id = 8) const float IHZ = 1.0;
const int QX = NX / 4;
const int PLANE = QX * NY;

layout(set = 0, binding = 0) uniform samplerBuffer quads;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(set = 0, binding = 2) uniform samplerBuffer floats;

void main() {
  const ivec3 g = ivec3(gl_GlobalInvocationID);
  if (g.x >= QX) return;
  const int idx = (g.z * NY + g.y) * QX + g.x;
  // Neighbours clamped: at a border the voxel itself (the one-sided difference's `c`).
  const vec4 c = texelFetch(quads, idx);
  const vec4 zl = texelFetch(quads, idx - (g.z > 0 ? PLANE : 0));
  const vec4 zh = texelFetch(quads, idx + (g.z + 1 < NZ ? PLANE : 0));
  const vec4 yl = texelFetch(quads, idx - (g.y > 0 ? QX : 0));
  const vec4 yh = texelFetch(quads, idx + (g.y + 1 < NY ? QX : 0));
  const float xl = texelFetch(floats, idx * 4 - (g.x > 0 ? 1 : 0)).x;
  const float xh = texelFetch(floats, idx * 4 + (g.x + 1 < QX ? 4 : 3)).x;
  const int x = g.x * 4;
  const float fy = (g.y == 0 || g.y == NY - 1) ? IHY : I2HY;
  const float fz = (g.z == 0 || g.z == NZ - 1) ? IHZ : I2HZ;
  const vec4 dy = (yh - yl) * fy, dz = (zh - zl) * fz;
  const float dx0 = x == 0 ? (c.y - c.x) * IHX : (c.y - xl) * I2HX;
  const float dx3 = x + 3 == NX - 1 ? (c.w - c.z) * IHX : (xh - c.z) * I2HX;
  dst[idx * 4 + 0] = vec4(c.x, dx0, dy.x, dz.x);
  dst[idx * 4 + 1] = vec4(c.y, (c.z - c.x) * I2HX, dy.y, dz.y);
  dst[idx * 4 + 2] = vec4(c.z, (c.w - c.y) * I2HX, dy.z, dz.z);
  dst[idx * 4 + 3] = vec4(c.w, dx3, dy.w, dz.w);
}
