#version 450
// Gradient pass: value and world-space gradient per voxel into the plane-ready sample
// field that servo/ reads (servo/sample_field.h: struct Sample = vec4 here).
// Central differences inside, one-sided differences at the volume borders; the same
// float operations in the same order as engine/cpu_gradient.cpp, so results agree
// bit for bit on an IEEE-conformant device.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_GRADIENT_WG_X, local_size_y = ISOTOUCH_GRADIENT_WG_Y,
       local_size_z = ISOTOUCH_GRADIENT_WG_Z) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(push_constant) uniform Push { GradientPush pc; };

float voxel(uint x, uint y, uint z) {
  return src[pc.src_offset + ((z - pc.src_z0) * pc.ny + y) * pc.nx + x];
}

// Derivative along one axis at index i of n, given the two neighbours' values.
float diff(uint i, uint n, float lo, float c, float hi, float inv_2h, float inv_h) {
  if (n < 2u) return 0.0;
  if (i == 0u) return (hi - c) * inv_h;
  if (i == n - 1u) return (c - lo) * inv_h;
  return (hi - lo) * inv_2h;
}

void main() {
  uvec3 g = gl_GlobalInvocationID;
  if (g.x >= pc.nx || g.y >= pc.ny || g.z >= pc.slab_nz) return;  // tail of rounded-up grid
  uint x = g.x, y = g.y, z = pc.z0 + g.z;
  float c = voxel(x, y, z);
  float xl = x > 0u ? voxel(x - 1u, y, z) : c;
  float xh = x + 1u < pc.nx ? voxel(x + 1u, y, z) : c;
  float yl = y > 0u ? voxel(x, y - 1u, z) : c;
  float yh = y + 1u < pc.ny ? voxel(x, y + 1u, z) : c;
  float zl = z > 0u ? voxel(x, y, z - 1u) : c;
  float zh = z + 1u < pc.nz ? voxel(x, y, z + 1u) : c;
  vec4 s;
  s.x = c;
  s.y = diff(x, pc.nx, xl, c, xh, pc.inv_2h_x, pc.inv_h_x);
  s.z = diff(y, pc.ny, yl, c, yh, pc.inv_2h_y, pc.inv_h_y);
  s.w = diff(z, pc.nz, zl, c, zh, pc.inv_2h_z, pc.inv_h_z);
  dst[pc.dst_offset + (g.z * pc.ny + y) * pc.nx + x] = s;
}
