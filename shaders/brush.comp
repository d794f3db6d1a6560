#version 450
// Brushes (layout: shaders/isotouch_shared.h, "brushes"; model:
// engine/brush.h). One 8x8x8 workgroup per touched 8^3 brick, one invocation per voxel.
// Every voxel inside the brush gets its new value from its own pre-edit value (read
// before it is written, by this invocation only) and, for smooth, its face neighbours
// from the pre-edit copy in binding 1: no read-after-write races. A voxel whose bits
// changed sets its brick's dirty flag. The same float operations, in the same order, as
// the CPU reference engine/brush_cpu.cpp (`precise`: no contraction into FMA).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_BRUSH_WG, local_size_y = ISOTOUCH_BRUSH_WG, local_size_z = ISOTOUCH_BRUSH_WG) in;

layout(std430, set = 0, binding = 0) buffer Vol { float vol[]; };
layout(std430, set = 0, binding = 1) readonly buffer Pre { float pre[]; };
layout(std430, set = 0, binding = 2) buffer Dirty { uint dirty[]; };
layout(push_constant) uniform Push { BrushPush pc; };

float toward(float v, float target, float step) {
  precise float r = v;
  if (v < target) r = min(v + step, target);
  else if (v > target) r = max(v - step, target);
  return r;
}

float pre_at(ivec3 q) {
  q = clamp(q, ivec3(0), ivec3(int(pc.nx) - 1, int(pc.ny) - 1, int(pc.nz) - 1));
  return pre[(uint(q.z) - pc.pre_z0) * pc.pre_h * pc.pre_w + (uint(q.y) - pc.pre_y0) * pc.pre_w + (uint(q.x) - pc.pre_x0) -
             pc.src_base];
}

void main() {
  const uvec3 b = uvec3(pc.b0x, pc.b0y, pc.b0z) + gl_WorkGroupID;
  const uvec3 g = b * ISOTOUCH_BRICK + gl_LocalInvocationID;
  if (g.x >= pc.nx || g.y >= pc.ny || g.z >= pc.nz) return;

  precise float dx = (float(g.x) - pc.cx) * pc.sx;
  precise float dy = (float(g.y) - pc.cy) * pc.sy;
  precise float dz = (float(g.z) - pc.cz) * pc.sz;
  precise float r = sqrt((dx * dx + dy * dy) + dz * dz);
  if (!(r < pc.radius)) return;
  precise float t = (r - pc.inner) * pc.inv_width;
  t = min(max(t, 0.0), 1.0);
  precise float w = 1.0 - (t * t) * (3.0 - 2.0 * t);

  const uint i = (g.z * pc.ny + g.y) * pc.nx + g.x - pc.vol_base;
  const float v = vol[i];
  precise float nv;
  if (pc.kind == ISOTOUCH_BRUSH_ADD || pc.kind == ISOTOUCH_BRUSH_CARVE) {
    precise float step = pc.amount * w;
    nv = toward(v, pc.target, step);
  } else if (pc.kind == ISOTOUCH_BRUSH_DRILL) {
    precise float f = 1.0 + max((v - pc.target) * pc.dens_sign, 0.0) * pc.inv_dens_scale;
    precise float step = (pc.amount * w) / f;
    nv = toward(v, pc.target, step);
  } else {  // smooth
    const ivec3 q = ivec3(g);
    precise float sum = ((((pre_at(q - ivec3(1, 0, 0)) + pre_at(q + ivec3(1, 0, 0))) + pre_at(q - ivec3(0, 1, 0))) +
                          pre_at(q + ivec3(0, 1, 0))) + pre_at(q - ivec3(0, 0, 1))) + pre_at(q + ivec3(0, 0, 1));
    precise float m = sum * (1.0 / 6.0);
    // A NaN/Inf neighbour leaves the voxel as it is (as engine/brush_cpu.cpp).
    nv = (isnan(m) || isinf(m)) ? v : v + (m - v) * (pc.amount * w);
  }
  if (floatBitsToUint(nv) != floatBitsToUint(v)) {
    vol[i] = nv;
    const uint flag = ((b.z - pc.box_b0z) * pc.box_by + (b.y - pc.b0y)) * pc.box_bx + (b.x - pc.b0x);
    atomicOr(dirty[flag], 1u);
  }
}
