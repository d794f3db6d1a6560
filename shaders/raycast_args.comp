#version 450
// Ray caster args: one invocation turns the hit count of raycast_march.comp into the
// indirect dispatch size of raycast_shade.comp (whole workgroups, rounded up), or the tile
// count of raycast_tiles.comp into the tiled march's (one workgroup per tile) and the block
// pass's (TILES_PER_GROUP tiles per workgroup).
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = 1, local_size_y = 1, local_size_z = 1) in;
layout(std430, set = 0, binding = 11) buffer Counter { RaycastCounter ctr; };
// The listed tiles and the tiled march's dispatch; then the block pass's (raycast_tiles.comp).
layout(std430, set = 0, binding = 14) buffer TileCounter { RaycastCounter tctr; RaycastCounter blocks; };
// Specialization constant: false: the shade pass's dispatch from the hit count (binding 11);
// true: the tiled march's, one workgroup per listed tile, and the block pass's,
// TILES_PER_GROUP tiles per workgroup (binding 14).
layout(constant_id = 0) const bool TILES = false;
layout(constant_id = 1) const uint TILES_PER_GROUP = 1u;

// A grid of groups_x x groups_y workgroups, groups_x <= 65535 (the least
// maxComputeWorkGroupCount[0] Vulkan allows; a 4096^2 frame can have 4.2M hits / 64).
void main() {
  if (TILES) {
    uint groups = tctr.count;
    tctr.groups_x = min(groups, 65535u);
    tctr.groups_y = groups == 0u ? 0u : (groups + 65534u) / 65535u;
    tctr.groups_z = 1u;
    uint bgroups = (groups + TILES_PER_GROUP - 1u) / TILES_PER_GROUP;
    blocks.groups_x = min(bgroups, 65535u);
    blocks.groups_y = bgroups == 0u ? 0u : (bgroups + 65534u) / 65535u;
    blocks.groups_z = 1u;
    return;
  }
  uint groups = (ctr.count + ISOTOUCH_RAYCAST_SHADE_WG - 1u) / ISOTOUCH_RAYCAST_SHADE_WG;
  ctr.groups_x = min(groups, 65535u);
  ctr.groups_y = groups == 0u ? 0u : (groups + 65534u) / 65535u;
  ctr.groups_z = 1u;
}
