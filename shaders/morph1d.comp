#version 450
// One axis of a separable grayscale dilation (max) or erosion (min) over a box window of
// `radius` voxels each side; border: clamp to edge. The running extremum starts at
// -inf (max) or +inf (min) and is updated with a comparison, taps from k = -r up, as
// engine/cpu_filters.cpp does: NaN voxels are skipped (a comparison with NaN is false).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_FILTER_WG_X, local_size_y = ISOTOUCH_FILTER_WG_Y,
       local_size_z = ISOTOUCH_FILTER_WG_Z) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { float dst[]; };
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
  bool is_max = pc.mode == ISOTOUCH_MORPH_MAX;
  float m = is_max ? uintBitsToFloat(0xff800000u) : uintBitsToFloat(0x7f800000u);
  for (int k = -r; k <= r; ++k) {
    float v = src[line + clamp(i + k, 0, n - 1) * stride];
    m = is_max ? (v > m ? v : m) : (v < m ? v : m);
  }
  dst[pc.dst_offset + (g.z * pc.ny + y) * pc.nx + x] = m;
}
