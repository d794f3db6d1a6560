#version 450
// Per-brick value range: for each 8^3 brick, (min, max) over its voxels widened by
// `halo` voxels on every side (clamped to the volume), so that the range covers every
// voxel the gradient stencil or a trilinear sample inside the brick reads.
// Loop order z, y, x and comparison updates from +inf / -inf, as engine/cpu_filters.cpp:
// NaN voxels are skipped; a brick of only NaN voxels gives (+inf, -inf).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_MINMAX_WG_X, local_size_y = ISOTOUCH_MINMAX_WG_Y,
       local_size_z = ISOTOUCH_MINMAX_WG_Z) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { float dst[]; };
layout(push_constant) uniform Push { BrickMinMaxPush pc; };

void main() {
  uvec3 b = gl_GlobalInvocationID;
  if (b.x >= pc.bx || b.y >= pc.by || b.z >= pc.slab_bz) return;
  uint bz = pc.bz0 + b.z;
  int h = int(pc.halo);
  int x0 = max(int(b.x * ISOTOUCH_BRICK) - h, 0), x1 = min(int(b.x * ISOTOUCH_BRICK) + int(ISOTOUCH_BRICK) + h, int(pc.nx));
  int y0 = max(int(b.y * ISOTOUCH_BRICK) - h, 0), y1 = min(int(b.y * ISOTOUCH_BRICK) + int(ISOTOUCH_BRICK) + h, int(pc.ny));
  int z0 = max(int(bz * ISOTOUCH_BRICK) - h, 0), z1 = min(int(bz * ISOTOUCH_BRICK) + int(ISOTOUCH_BRICK) + h, int(pc.nz));
  float mn = uintBitsToFloat(0x7f800000u), mx = uintBitsToFloat(0xff800000u);
  for (int z = z0; z < z1; ++z)
    for (int y = y0; y < y1; ++y) {
      uint row = pc.src_offset + ((uint(z) - pc.src_z0) * pc.ny + uint(y)) * pc.nx;
      for (int x = x0; x < x1; ++x) {
        float v = src[row + uint(x)];
        mn = v < mn ? v : mn;
        mx = v > mx ? v : mx;
      }
    }
  uint o = pc.dst_offset + 2u * ((b.z * pc.by + b.y) * pc.bx + b.x);
  dst[o] = mn;
  dst[o + 1u] = mx;
}
