#version 450
// Brick min/max, second step: per 8^3 brick of the slab, (min, max) over the row ranges of
// minmax_rows.comp for z in [8 bz - halo, 8 bz + 8 + halo) and y likewise (clamped), z then
// y increasing: with x increasing inside each row this is the CPU's z, y, x order, so the
// first voxel of the extreme value wins as in engine/cpu_filters.cpp (-0 against +0 too).
// Rows read through a texel buffer (R32F: min at 2 i, max at 2 i + 1), one invocation per
// brick, 1-D workgroups; writes (min, max) per brick as brick_minmax.comp.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int BX = 1;  // bricks along x

layout(set = 0, binding = 0) uniform samplerBuffer rows;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec2 dst[]; };
layout(push_constant) uniform Push { BrickMinMaxPush pc; };

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  const int by = int(pc.by);
  if (t >= BX * by) return;
  const int yb = t / BX, b = t - yb * BX;
  const int zb = int(gl_GlobalInvocationID.z);  // brick layer within the slab
  const int bz = int(pc.bz0) + zb;
  const int h = int(pc.halo), ny = int(pc.ny), nz = int(pc.nz), src_z0 = int(pc.src_z0);
  const int B = int(ISOTOUCH_BRICK);
  const int y0 = max(yb * B - h, 0), y1 = min(yb * B + B + h, ny);
  const int z0 = max(bz * B - h, 0), z1 = min(bz * B + B + h, nz);
  float mn = uintBitsToFloat(0x7f800000u), mx = uintBitsToFloat(0xff800000u);
  for (int z = z0; z < z1; ++z)
    for (int y = y0; y < y1; ++y) {
      const int i = 2 * (((z - src_z0) * ny + y) * BX + b);
      const float lo = texelFetch(rows, i).x, hi = texelFetch(rows, i + 1).x;
      mn = lo < mn ? lo : mn;
      mx = hi > mx ? hi : mx;
    }
  dst[int(pc.dst_offset) / 2 + (zb * by + yb) * BX + b] = vec2(mn, mx);
}
