#version 450
// One axis of the separable Gaussian: dst[i] = sum_{k=-r..r} w[k + r] * src[clamp(i + k)],
// the normalised weights precomputed on the CPU (engine/cpu_filters.cpp gaussian_kernel)
// and passed in a buffer. The accumulator is `precise` (no FMA contraction, no
// reassociation) and the taps are summed from k = -r up, exactly as
// engine/cpu_filters.cpp does, so the result agrees bit for bit on an IEEE device.
// Border: clamp to edge.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_FILTER_WG_X, local_size_y = ISOTOUCH_FILTER_WG_Y,
       local_size_z = ISOTOUCH_FILTER_WG_Z) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { float dst[]; };
layout(std430, set = 0, binding = 2) readonly buffer Weights { float w[]; };
layout(push_constant) uniform Push { Filter1dPush pc; };

void main() {
  uvec3 g = gl_GlobalInvocationID;
  if (g.x >= pc.nx || g.y >= pc.ny || g.z >= pc.slab_nz) return;
  uint x = g.x, y = g.y, z = pc.z0 + g.z;
  int n = int(pc.axis == 0u ? pc.nx : (pc.axis == 1u ? pc.ny : pc.nz));
  int i = int(pc.axis == 0u ? x : (pc.axis == 1u ? y : z));
  int r = int(pc.radius);
  // Voxel j along the axis is src[line + j * stride]: no per-tap branch on the axis.
  int stride = int(pc.axis == 0u ? 1u : (pc.axis == 1u ? pc.nx : pc.nx * pc.ny));
  int line = int(pc.src_offset + ((z - pc.src_z0) * pc.ny + y) * pc.nx + x) - i * stride;
  precise float acc = 0.0;
  for (int k = -r; k <= r; ++k) {
    float v = src[line + clamp(i + k, 0, n - 1) * stride];
    precise float term = w[pc.w_offset + uint(k + r)] * v;
    acc = acc + term;
  }
  dst[pc.dst_offset + (g.z * pc.ny + y) * pc.nx + x] = acc;
}
