#version 450
// A dense pass's memory traffic and nothing else: four voxels of an x-row per invocation
// read through the texel buffer, no arithmetic, and per OUT: 0 one vec4 sample per voxel
// written (the gradient's 4 + 16 B per voxel), 1 the four floats written as one vec4 (a
// filter's 4 + 4 B, as filter_x4.comp), 2 nothing written (brick min/max's 4 B read; a store
// no voxel value takes keeps the loads). `bench engine` times it as lavapipe's floor for the
// dense passes (what the same loads and stores cost on this device), beside memcpy of the
// same bytes. Layout as gradient_x4.comp.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int NX = 1;
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
layout(constant_id = 3) const bool VEC4_IN = false;  // as gradient_x4.comp: one fetch per quad
layout(constant_id = 4) const int OUT = 0;            // 0 samples, 1 floats, 2 no output
const int QX = (NX + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS;

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(push_constant) uniform Push { DensePush pc; };

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  if (t >= QX * NY) return;
  const int y = t / QX, x0 = (t - y * QX) * ISOTOUCH_DENSE_VOXELS;
  const int zs = int(gl_GlobalInvocationID.z);
  const int z = int(pc.z0) + zs;
  const int row = int(pc.src_offset) + (z - int(pc.src_z0)) * NX * NY + y * NX;
  const ivec4 xs = min(ivec4(x0) + ivec4(0, 1, 2, 3), ivec4(NX - 1));
  const vec4 c = VEC4_IN ? texelFetch(src, (row + x0) / 4)
                         : vec4(texelFetch(src, row + xs.x).x, texelFetch(src, row + xs.y).x,
                                texelFetch(src, row + xs.z).x, texelFetch(src, row + xs.w).x);
  const uint o = pc.dst_offset + uint((zs * NY + y) * NX + x0);
  if (OUT == 2) {
    if (c.x + c.y + c.z + c.w == -3.0e38) dst[o / 4u] = c;  // never on finite voxels of a volume
    return;
  }
  if (OUT == 1) {
    // Whole quads (NX a multiple of 4): one 16 B store; else the row's floats one by one.
    if (NX % 4 == 0) {
      dst[o / 4u] = c;
    } else {
      for (int j = 0; j < 4; ++j)
        if (x0 + j < NX) dst[(o + uint(j)) / 4u][(o + uint(j)) % 4u] = c[j];
    }
    return;
  }
  if (x0 + 3 < NX) {
    dst[o] = c.xxxx;
    dst[o + 1u] = c.yyyy;
    dst[o + 2u] = c.zzzz;
    dst[o + 3u] = c.wwww;
  } else {
    for (int j = 0; j < 4; ++j)
      if (x0 + j < NX) dst[o + uint(j)] = vec4(c[j]);
  }
}
