#version 450
// The floor of a ray-caster frame on this device (tests/bench_raycast_floor.cpp): one
// invocation per pixel does FETCHES texel fetches of voxel values (the gather path the ray
// caster's voxel() takes; with VEC4, of 4 floats each) and one store, and nothing else of a ray: no ray set-up, no
// march, no refinement, no shading.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = 1, local_size_z = 1) in;
layout(set = 0, binding = 0) uniform samplerBuffer vals;
layout(std430, set = 0, binding = 1) buffer Out { uint img[]; };
layout(push_constant) uniform Push { RaycastFloorPush pc; };
layout(constant_id = 0) const int FETCHES = 0;
layout(constant_id = 1) const int NVOX_MASK = 0;  // texels - 1, a power of two
// The texel buffer viewed as R32G32B32A32_SFLOAT: each fetch reads 4 floats (a quad of voxels).
layout(constant_id = 2) const bool VEC4 = false;

void main() {
  uint x = gl_GlobalInvocationID.x, y = gl_WorkGroupID.y;
  if (x >= pc.width) return;
  uint pix = y * pc.width + x;
  // Neighbouring pixels read neighbouring voxels, as neighbouring rays do.
  int base = int(pix) & NVOX_MASK;
  float acc = 0.0;
  for (int i = 0; i < FETCHES; ++i) {
    vec4 q = texelFetch(vals, (base + i * 67) & NVOX_MASK);
    acc += VEC4 ? (q.x + q.y) + (q.z + q.w) : q.x;
  }
  img[pix] = floatBitsToUint(acc);
}
