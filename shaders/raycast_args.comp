#version 450
// Ray caster pass 2 of 4: one invocation turns the hit count of raycast_march.comp
// into the indirect dispatch size of raycast_shade.comp (whole workgroups, rounded up).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = 1, local_size_y = 1, local_size_z = 1) in;
layout(std430, set = 0, binding = 11) buffer Counter { RaycastCounter ctr; };

// A grid of groups_x x groups_y workgroups, groups_x <= 65535 (the least
// maxComputeWorkGroupCount[0] Vulkan allows; a 4096^2 frame can have 4.2M hits / 64).
void main() {
  uint groups = (ctr.count + ISOTOUCH_RAYCAST_SHADE_WG - 1u) / ISOTOUCH_RAYCAST_SHADE_WG;
  ctr.groups_x = min(groups, 65535u);
  ctr.groups_y = groups == 0u ? 0u : (groups + 65534u) / 65535u;
  ctr.groups_z = 1u;
}
