#version 450
// One axis of a separable filter (filter_x4.glsl), four voxels of an x-row per invocation
// over every row of a z-slab (isotouch_shared.h DensePush).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(push_constant) uniform Push { DensePush pc; };
#include "filter_x4.glsl"

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  if (t >= QX * NY) return;
  const int y = t / QX;
  const int x0 = (t - y * QX) * ISOTOUCH_DENSE_VOXELS;
  const int zs = int(gl_GlobalInvocationID.z);  // slice within the slab
  const int z = int(pc.z0) + zs;
  const int src0 = int(pc.src_offset) - int(pc.src_z0) * NX * NY;
  const vec4 acc = filter_quad(x0, y, z, src0);
  store_quad(pc.dst_offset + uint((zs * NY + y) * NX + x0), x0, acc, pc.vec4_out != 0u);
}
