#version 450
// Brick min/max, first step: for every brick column bx of every x-row (y, z) of the slab's
// source slices, (min, max) over x in [8 bx - halo, 8 bx + 8 + halo) clamped to the row,
// x increasing, comparison updates from +inf / -inf as engine/cpu_filters.cpp (NaN skipped).
// minmax_bricks.comp combines the rows of each brick. Texel-buffer input, one invocation
// per (row, brick column), 1-D workgroups (isotouch_shared.h BrickMinMaxPush; pad0 = the
// source slices in the binding).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int BX = 1;  // bricks along x: the row / column split folds

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Rows { vec2 rows[]; };
layout(push_constant) uniform Push { BrickMinMaxPush pc; };

void main() {
  const int t = int(gl_GlobalInvocationID.x);
  const int ny = int(pc.ny), nx = int(pc.nx);
  if (t >= BX * ny) return;
  const int y = t / BX, b = t - y * BX;
  const int zl = int(gl_GlobalInvocationID.z);  // slice within the source binding
  const int h = int(pc.halo);
  const int x0 = max(b * int(ISOTOUCH_BRICK) - h, 0), x1 = min(b * int(ISOTOUCH_BRICK) + int(ISOTOUCH_BRICK) + h, nx);
  const int row = int(pc.src_offset) + (zl * ny + y) * nx;
  float mn = uintBitsToFloat(0x7f800000u), mx = uintBitsToFloat(0xff800000u);
  for (int x = x0; x < x1; ++x) {
    const float v = texelFetch(src, row + x).x;
    mn = v < mn ? v : mn;
    mx = v > mx ? v : mx;
  }
  rows[(zl * ny + y) * BX + b] = vec2(mn, mx);
}
