#version 450
// Gradient pass (gradient_x4.glsl) on the quads of a work list (work_list.glsl): the
// sparse chain's samples over the candidate bricks, dense-addressed (the same element as
// the dense pass).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(push_constant) uniform Push { ListPush pc; };
#include "gradient_x4.glsl"
#include "work_list.glsl"

void main() {
  int x0, y, z;
  if (!list_quad(x0, y, z)) return;
  const int src0 = int(pc.src_offset) - int(pc.src_z0) * NX * NY;
  gradient_quad(x0, y, z, src0, pc.dst_offset + uint(((z - int(pc.z0)) * NY + y) * NX + x0));
}
