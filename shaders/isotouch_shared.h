// isotouch_shared.h - one header read by both GLSL (glslangValidator) and C++.
//
// Workgroup sizes and the push-constant block of every compute pass live here, so the
// shaders and engine/ cannot drift apart. engine/gpu_layout.cpp pins the C++ view of
// every struct with static_assert on sizeof/offsetof (std430 rules: all members here
// are 4-byte scalars, so offsets are 4 * member index).
#ifndef ISOTOUCH_SHARED_H
#define ISOTOUCH_SHARED_H

#ifdef __cplusplus
#include <cstdint>
namespace isotouch::gpu {
using uint = std::uint32_t;
#endif

// Gradient pass workgroup: 8x8x4 = 256 invocations. x fastest matches the voxel order
// (x fastest, then y, then z), so neighbouring invocations read neighbouring floats.
#define ISOTOUCH_GRADIENT_WG_X 8
#define ISOTOUCH_GRADIENT_WG_Y 8
#define ISOTOUCH_GRADIENT_WG_Z 4

// One dispatch of the gradient pass covers one z-slab of the volume, because a single
// storage-buffer binding may not exceed maxStorageBufferRange (128 MiB on lavapipe).
//   src: float voxels, index space, x fastest. Binding 0 starts at slice src_z0 of the
//        volume (rounded down to the offset alignment; src_offset elements remain).
//   dst: one vec4 (value, dv/dx, dv/dy, dv/dz) per voxel, gradient in [value units / m]
//        in the volume frame; binding 1 starts at slice z0 (+ dst_offset elements).
struct GradientPush {
  uint nx;          // volume size in voxels along x
  uint ny;          // ... along y
  uint nz;          // ... along z (whole volume, for the border rule)
  uint z0;          // first slice of this slab (index space)
  uint slab_nz;     // slices in this slab
  uint src_z0;      // first slice present in the src binding
  uint src_offset;  // elements between the src binding start and slice src_z0
  uint dst_offset;  // elements between the dst binding start and slice z0
  float inv_2h_x;   // 1 / (2 spacing_x) [1/m]: central difference
  float inv_2h_y;
  float inv_2h_z;
  float inv_h_x;    // 1 / spacing_x [1/m]: one-sided difference at the borders
  float inv_h_y;
  float inv_h_z;
  uint pad0;        // keeps the block a multiple of 16 bytes
  uint pad1;
};

// 1-D filter passes (gaussian1d.comp, morph1d.comp): one axis of a separable filter,
// same z-slab scheme as the gradient (src binding holds slices [src_z0, ...) with a halo
// of `radius` slices each side when axis == 2). Border: clamp to edge (index clamped
// into [0, n - 1] along the axis).
#define ISOTOUCH_FILTER_WG_X 8
#define ISOTOUCH_FILTER_WG_Y 8
#define ISOTOUCH_FILTER_WG_Z 4
#define ISOTOUCH_MORPH_MAX 1u  // dilation: maximum over the window
#define ISOTOUCH_MORPH_MIN 2u  // erosion: minimum over the window
struct Filter1dPush {
  uint nx;          // volume size in voxels (whole volume)
  uint ny;
  uint nz;
  uint z0;          // first slice of this slab
  uint slab_nz;     // slices in this slab
  uint src_z0;      // first slice present in the src binding
  uint src_offset;  // elements between the src binding start and slice src_z0
  uint dst_offset;  // elements between the dst binding start and slice z0
  uint axis;        // 0 = x, 1 = y, 2 = z
  uint radius;      // taps on each side of the centre
  uint w_offset;    // gaussian: first weight of this axis' kernel in the weights buffer
  uint mode;        // morph: ISOTOUCH_MORPH_MAX or ISOTOUCH_MORPH_MIN
};

// Per-brick min/max (brick_minmax.comp): one invocation per 8^3 brick (OpenVDB's leaf
// size), reading the brick's voxels widened by `halo` voxels on every side (clamped to
// the volume); writes (min, max) as two floats per brick, bricks x fastest. A slab is a
// range of brick layers (8 slices each).
#define ISOTOUCH_BRICK 8u
#define ISOTOUCH_MINMAX_WG_X 4
#define ISOTOUCH_MINMAX_WG_Y 4
#define ISOTOUCH_MINMAX_WG_Z 4
struct BrickMinMaxPush {
  uint nx;          // volume size in voxels
  uint ny;
  uint nz;
  uint bx;          // bricks along x: ceil(nx / 8)
  uint by;
  uint bz0;         // first brick layer of this slab
  uint slab_bz;     // brick layers in this slab
  uint src_z0;      // first slice present in the src binding
  uint src_offset;  // elements between the src binding start and slice src_z0
  uint dst_offset;  // floats between the dst binding start and brick layer bz0
  uint halo;        // voxels added on every side of a brick
  uint pad0;
};

#ifdef __cplusplus
}  // namespace isotouch::gpu
#endif
#endif  // ISOTOUCH_SHARED_H
