// work_list.glsl - the quads of a sparse filter pass (filter_list_x4.comp, isotouch_shared.h
// ListPush): binding 2 holds the work units, two texels each: the row y + NY z and
// q0 * ISOTOUCH_LIST_PACK + n, the row's quads q0 .. q0 + n - 1 (n <= ISOTOUCH_LIST_QUADS;
// integers below 2^24, exact in a float texel). ISOTOUCH_LIST_INVOCATIONS consecutive
// invocations take one unit; invocation `lane` of it computes quads lane, lane +
// ISOTOUCH_LIST_INVOCATIONS, ... (fewer invocations, each with more work: llvmpipe pays per
// invocation). The dispatch is 2-D (x fastest, pc.groups_x workgroups per y) to exceed
// maxComputeWorkGroupCount[0] units.
layout(set = 0, binding = 2) uniform samplerBuffer work;

// This invocation's unit: row (y, z), its first quad q0 and its quads n, and the lane (the
// first of the unit's quads this invocation computes); false if none.
bool list_unit(out int y, out int z, out int q0, out int n, out int lane) {
  const uint t = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * pc.groups_x * uint(ISOTOUCH_DENSE_WG);
  const uint u = t / ISOTOUCH_LIST_INVOCATIONS;
  lane = int(t % ISOTOUCH_LIST_INVOCATIONS);
  y = 0;
  z = 0;
  q0 = 0;
  n = 0;
  if (u >= pc.units) return false;
  const int i = 2 * int(pc.unit0 + u);
  const int row = int(texelFetch(work, i).x);
  const int packed = int(texelFetch(work, i + 1).x);
  n = packed % int(ISOTOUCH_LIST_PACK);
  if (lane >= n) return false;
  q0 = packed / int(ISOTOUCH_LIST_PACK);
  z = row / NY;
  y = row - z * NY;
  return true;
}
