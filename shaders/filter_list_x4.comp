#version 450
// One axis of a separable filter (filter_x4.glsl) on the quads of a work list
// (work_list.glsl): the sparse chain's filters over the candidate bricks dilated by the
// stencil, dense-addressed (the same element as the dense pass), each voxel once.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(push_constant) uniform Push { ListPush pc; };
#include "filter_x4.glsl"
#include "work_list.glsl"

void main() {
  int y, z, q0, n, lane;
  if (!list_unit(y, z, q0, n, lane)) return;
  const int src0 = int(pc.src_offset) - int(pc.src_z0) * NX * NY;
  for (int k = 0; k < int(ISOTOUCH_LIST_QUADS / ISOTOUCH_LIST_INVOCATIONS); ++k) {
    const int q = lane + k * int(ISOTOUCH_LIST_INVOCATIONS);
    if (q >= n) break;
    const int x0 = (q0 + q) * ISOTOUCH_DENSE_VOXELS;
    const vec4 acc = filter_quad(x0, y, z, src0);
    store_quad(pc.dst_offset + uint(((z - int(pc.z0)) * NY + y) * NX + x0), x0, acc, pc.vec4_out != 0u);
  }
}
