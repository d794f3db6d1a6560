// work_list.glsl - the quads of a sparse filter pass (filter_list_x4.comp) (isotouch_shared.h ListPush): binding 2 holds
// the work units, two texels each: the row y + NY z and q0 * ISOTOUCH_LIST_PACK + n, the
// row's quads q0 .. q0 + n - 1 (n <= ISOTOUCH_LIST_QUADS; integers below 2^24, exact in a
// float texel). ISOTOUCH_LIST_QUADS consecutive invocations take one unit, one quad each:
// the lanes of one SIMD vector of llvmpipe share a row. The dispatch is 2-D (x fastest,
// pc.groups_x workgroups per y) to exceed maxComputeWorkGroupCount[0] units.
layout(set = 0, binding = 2) uniform samplerBuffer work;

// The quad of this invocation: voxels x0 .. x0 + 3 of row (y, z); false if none.
bool list_quad(out int x0, out int y, out int z) {
  const uint t = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * pc.groups_x * uint(ISOTOUCH_DENSE_WG);
  const uint u = t / ISOTOUCH_LIST_QUADS, lane = t % ISOTOUCH_LIST_QUADS;
  x0 = 0;
  y = 0;
  z = 0;
  if (u >= pc.units) return false;
  const int i = 2 * int(pc.unit0 + u);
  const int row = int(texelFetch(work, i).x);
  const int packed = int(texelFetch(work, i + 1).x);
  if (int(lane) >= packed % int(ISOTOUCH_LIST_PACK)) return false;
  z = row / NY;
  y = row - z * NY;
  x0 = (packed / int(ISOTOUCH_LIST_PACK) + int(lane)) * ISOTOUCH_DENSE_VOXELS;
  return true;
}
