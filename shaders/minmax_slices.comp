#version 450
// Brick min/max, second step of the whole-field form (minmax_segments.comp): per 8^3 brick,
// (min, max) over its segments of slices z = 8 bz - halo .. 8 bz + 7 + halo (clamped), z
// increasing - with each segment reduced in y, x order this is the CPU's z, y, x order, so
// the result is engine/cpu_filters.cpp's bit for bit (first of equal values kept, NaN
// skipped). One invocation per brick, 1-D workgroups over the bricks of a layer, z the
// layer; writes (min, max) per brick as brick_minmax.comp. Push: BrickMinMaxPush (nz, bx,
// by, halo; bz0 = 0, the whole volume).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Seg { vec2 seg[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec2 dst[]; };
layout(push_constant) uniform Push { BrickMinMaxPush pc; };

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  const int bx = int(pc.bx), by = int(pc.by);
  if (t >= bx * by) return;
  const int bz = int(gl_GlobalInvocationID.z);
  const int B = int(ISOTOUCH_BRICK), h = int(pc.halo), nz = int(pc.nz);
  const int z0 = max(bz * B - h, 0), z1 = min(bz * B + B + h, nz);
  float mn = uintBitsToFloat(0x7f800000u), mx = uintBitsToFloat(0xff800000u);
  for (int z = z0; z < z1; ++z) {
    const vec2 s = seg[z * bx * by + t];
    mn = s.x < mn ? s.x : mn;
    mx = s.y > mx ? s.y : mx;
  }
  dst[bz * bx * by + t] = vec2(mn, mx);
}
