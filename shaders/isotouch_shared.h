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

// Dense passes shaped for llvmpipe and real GPUs alike (gaussian_x4.comp, gradient_x4.comp):
// the source is read through a uniform texel buffer (R32_SFLOAT, texelFetch), each
// invocation computes ISOTOUCH_DENSE_VOXELS consecutive voxels of one x-row (vec4 work),
// workgroups are 1-D (ISOTOUCH_DENSE_WG x 1 x 1) over the rows of a slab: invocation t of
// dispatch row z covers row y = t / qx, voxels x0 = 4 (t % qx) .. x0 + 3 (qx = ceil(nx / 4));
// lanes past nx read clamped voxels and store nothing. Specialization constants: the
// volume's size (constant_id 0, 1, 2: nx, ny, nz; the index arithmetic folds), and for the
// Gaussian its axis (3), radius (4) and weights (5 + k: weight k of the 2 radius + 1 taps),
// so the tap loop unrolls with its weights folded in; radii above ISOTOUCH_DENSE_MAX_RADIUS
// take gaussian1d.comp. Same z-slab scheme as the 1-D filters; the push constants' sizes
// are informative (the shaders read the specialised ones).
#define ISOTOUCH_DENSE_WG 64
#define ISOTOUCH_DENSE_VOXELS 4
#define ISOTOUCH_DENSE_MAX_RADIUS 16
struct DensePush {
  uint nx;          // volume size in voxels (whole volume)
  uint ny;
  uint nz;
  uint z0;          // first slice of this slab
  uint slab_nz;     // slices in this slab
  uint src_z0;      // first slice present in the src binding
  uint src_offset;  // elements between the src binding start and slice src_z0
  uint dst_offset;  // elements (floats or vec4 samples) between the dst binding start and slice z0
  uint qx;          // invocations per x-row: ceil(nx / ISOTOUCH_DENSE_VOXELS)
  uint vec4_out;    // gaussian: 1 if every row starts 16-byte aligned in dst (one vec4 store)
  float inv_2h_x;   // gradient: 1 / (2 spacing) [1/m], central difference
  float inv_2h_y;
  float inv_2h_z;
  float inv_h_x;    // gradient: 1 / spacing [1/m], one-sided difference at the borders
  float inv_h_y;
  float inv_h_z;
};

// The sparse chain's filters on work lists (filter_list_x4.comp, shaders/work_list.glsl):
// the dense filters' quads, but only those of the rows a list names.
// A unit is a run of at most ISOTOUCH_LIST_QUADS quads of one row; ISOTOUCH_LIST_INVOCATIONS
// consecutive invocations take one unit (ISOTOUCH_LIST_QUADS / ISOTOUCH_LIST_INVOCATIONS
// quads each at most). Buffers are dense-addressed as in DensePush.
#define ISOTOUCH_LIST_QUADS 8u
#define ISOTOUCH_LIST_INVOCATIONS 4u
#define ISOTOUCH_LIST_PACK 16u  // a unit's second texel: q0 * ISOTOUCH_LIST_PACK + quads
// The fused Gaussian (gauss_fused_list.comp): x, y and z in one pass over columns of quads,
// radii up to this many voxels a side on every axis; wider kernels take the separate passes.
#define ISOTOUCH_FUSED_MAX_RADIUS 4
struct ListPush {
  uint z0;          // first slice of this slab (dst_offset is the element of its voxel 0)
  uint src_z0;      // first slice present in the src binding
  uint src_offset;  // elements between the src binding start and slice src_z0
  uint dst_offset;  // elements between the dst binding start and slice z0
  uint unit0;       // first unit of this dispatch in the list binding
  uint units;       // units of this dispatch (all in slices z0 ..)
  uint groups_x;    // workgroups along x of the 2-D dispatch
  uint vec4_out;    // 1 if every row starts 16-byte aligned in dst (one vec4 store)
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

// ---- raycast -------------------------------------------
// First-hit isosurface ray caster: five passes (raycast_tiles, raycast_march, raycast_args,
// raycast_shade, raycast_overlay .comp; shared code raycast_common.glsl; CPU reference
// engine/raycast_cpu.cpp). march and overlay: one invocation per pixel, rows of 64 pixels
// (long 1-D workgroups run faster on llvmpipe than 8x8 tiles); the march shades its hits;
// shade: one per pixel the march listed (rays its loop budget stopped),
// ISOTOUCH_RAYCAST_SHADE_WG per workgroup, dispatched indirectly from RaycastCounter. Bindings (every pass, one layout): 0 params (one RaycastParams), 1 values
// (uniform texel buffer, R32_SFLOAT per voxel, x fastest; R32G32B32A32_SFLOAT, 4 voxels per
// texel, where they exceed maxTexelBufferElements: VALS4), 2 cell distances (uniform texel
// buffer, R32_SFLOAT: 4 trilinear cells per texel, 6 bits each from the low end, as an exact
// integer; see ISOTOUCH_RAYCAST_DIST_MAX),
// 3 primitives (uniform texel buffer, R32G32B32A32_UINT: 4 texels per RaycastPrim), 4 image (RGBA8 per pixel, R
// in the low byte), 5 depth (float per pixel: ray parameter t [m] of the isosurface hit,
// -1 if none), 6-8 linear colour R, G, B (float per pixel), 9 listed pixels (uint, count in
// RaycastCounter), 10 per listed pixel the sample k its march stopped at | 1 << 30, 11 one RaycastCounter, 12 the
// voxels as quads (uniform texel buffer, R32G32B32A32_SFLOAT; shaders/raycast_common.glsl),
// 13 per tile of pixels the ray parameter t [m] before which no sample can be inside,
// 14 the tiles' RaycastCounter (listed tiles, the march's indirect dispatch), 15 the tiles
// that may hold a hit (ty << 16 | tx, in no order), 16 the overlay stages' colour and depth
// per pixel (vec4; raycast_overlay.comp).
#define ISOTOUCH_RAYCAST_WG_X 64
#define ISOTOUCH_RAYCAST_WG_Y 1
#define ISOTOUCH_RAYCAST_SHADE_WG 64
#define ISOTOUCH_RAYCAST_BINDINGS 17
// Tile starts (raycast_tiles.comp): square tiles of TILE pixels per side, x fastest, the
// first at pixel (0, 0); the cone march of a tile takes at most TILE_STEPS steps. With tile
// starts the march runs one workgroup (TILE^2 = WG_X invocations) per listed tile.
#define ISOTOUCH_RAYCAST_TILE 8u
#define ISOTOUCH_RAYCAST_TILE_STEPS 128u
// Block starts: each listed tile's blocks of BLOCK x BLOCK pixels get a start of their own
// (the same cone march from the tile's start, a narrower cone: closer to the surface).
#define ISOTOUCH_RAYCAST_BLOCK 4u
#define ISOTOUCH_RAYCAST_SKIP 1u      // flags: empty-space skipping (cell distances, binding 2; the
                                      // CPU reference reads it, the GPU picks its march pipeline)
#define ISOTOUCH_RAYCAST_CLIP 2u      // flags: clip the half-space dot(n, p) + d > 0 away
#define ISOTOUCH_RAYCAST_TILES 4u     // flags: with SKIP, each pixel's march starts at its tile's
                                      // start (binding 13; GPU only: the picture is the same)
#define ISOTOUCH_RAYCAST_BISECTIONS 6  // bisections of a hit's refinement (refine(); the CPU reference the same)
#define ISOTOUCH_RAYCAST_BGRA 8u      // flags: pixels packed B, G, R, A from the low byte (a
                                      // B8G8R8A8 swapchain's order; GPU only)
// Empty-space skipping: trilinear cells c in [-1, n] per axis (n + 2 cells, stored at c + 1,
// x fastest; one byte per cell on the host, 4 cells per float texel on the device). Cell c (corners c .. c + 1) is active
// if one of its 8 corner values (background outside the grid) can be inside, with a margin
// for the rounding of the lerps; its byte is the chessboard distance [cells] to the nearest
// active cell (0: active), capped at ISOTOUCH_RAYCAST_DIST_MAX (engine/raycast.cpp; each
// level costs the host one pass over the cells' bit set, and a jump of 31 cells is plenty).
#define ISOTOUCH_RAYCAST_DIST_MAX 32u
// llvmpipe ends all loops of a shader invocation after 65535 iterations in all (counted per
// vector of 8 lanes, per pass): the host refuses a step that lets a ray take more lattice
// samples than this (the march is one flat loop of at most MAX_SAMPLES + 1 trips; the other
// loops of the march pass are the two box intersections, 3 trips each).
#define ISOTOUCH_RAYCAST_MAX_SAMPLES 60000u
// The largest march step [voxels, index space]: the refinement reads the 3x3x3 voxels around
// its bracket of one step, whose points must stay within 2 cells per axis (raycast_common.glsl).
#define ISOTOUCH_RAYCAST_MAX_STEP 0.9f
#define ISOTOUCH_RAYCAST_PRIM_SPHERE 1u   // a = centre, r0 = radius
#define ISOTOUCH_RAYCAST_PRIM_DISC 2u     // a = centre, b = unit normal, r0 = radius
#define ISOTOUCH_RAYCAST_PRIM_CAPSULE 3u  // a, b = segment ends, r0 = radius
#define ISOTOUCH_RAYCAST_PRIM_CONE 4u     // a = base centre, b = apex, r0 = base radius
#define ISOTOUCH_RAYCAST_MAX_PRIMS 1024u
// Per-frame parameters: a std140 uniform buffer (binding 0; more than the 128 guaranteed push
// bytes; std140 = std430 here: 4-byte scalars only, size a multiple of 16).
// Frames: eye, basis, clip plane and primitives in grid-world [m]; the march runs in index
// space p_idx = (p - origin) * inv_spacing, with t the ray parameter in metres.
struct RaycastParams {
  uint width;        // image size [pixels]
  uint height;
  uint nx;           // volume size [voxels]
  uint ny;
  uint nz;
  uint bx;           // bricks per axis: ceil(n / 8)
  uint by;
  uint bz;
  float tau;         // isovalue (value units)
  float inside_sign; // +1: value > tau is inside; -1: value < tau is inside
  float background;  // value of every voxel outside the grid (core::FieldView)
  float step_vox;    // march step, index-space length [voxels]
  float eye_x;       // camera position, grid-world [m]
  float eye_y;
  float eye_z;
  float focal_px;    // (height / 2) / tan(fov_y / 2) [pixels]
  float fwd_x;       // unit view direction, grid-world
  float fwd_y;
  float fwd_z;
  float clip_d;      // clip plane: points with dot(clip_n, p) + clip_d > 0 are removed [m]
  float right_x;     // unit image-right direction
  float right_y;
  float right_z;
  float clip_nx;     // clip plane unit normal, grid-world
  float up_x;        // unit image-up direction
  float up_y;
  float up_z;
  float clip_ny;
  float origin_x;    // grid-world position of voxel (0,0,0) [m]
  float origin_y;
  float origin_z;
  float clip_nz;
  float inv_sp_x;    // 1 / spacing [1/m]
  float inv_sp_y;
  float inv_sp_z;
  float surf_r;      // surface albedo, linear 0..1
  float surf_g;
  float surf_b;
  float bg_r;        // background colour
  float bg_g;
  float bg_b;
  float cap_r;       // colour of the cut face where the clip plane opens the object
  float cap_g;
  float cap_b;
  float act_lo_x;    // index-space box of the active cells (skipping: no sample outside it
  float act_lo_y;    //   can be inside; make_params: the volume's box [-1, n], the GPU
  float act_lo_z;    //   caster narrows it; the CPU reference does not read it)
  float act_hi_x;
  float act_hi_y;
  float act_hi_z;
  float pad0;
  float pad1;
};
// One overlay primitive (HIP, VHIP, plane disc, force arrow, path, contact points).
struct RaycastPrim {
  uint kind;         // ISOTOUCH_RAYCAST_PRIM_*
  float r0;          // radius [m]
  float alpha;       // opacity 0..1 (1 opaque)
  float pad0;
  float ax;          // point a, grid-world [m]
  float ay;
  float az;
  float cr;          // colour, linear 0..1
  float bx;          // point or unit normal b, grid-world
  float by;
  float bz;
  float cg;
  float pad1;
  float pad2;
  float pad3;
  float cb;
};
// Push constants: what changes between frames of the same parameters.
struct RaycastPush {
  uint flags;        // ISOTOUCH_RAYCAST_SKIP | ISOTOUCH_RAYCAST_CLIP
  uint prim_count;   // primitives given (<= ISOTOUCH_RAYCAST_MAX_PRIMS); overlay pass: binding 3's
                     //   two lists, opaque length << 16 | total (raycast_overlay.comp)
  uint x0;           // march pass: pixel of its invocation (0, 0); the dispatch covers only
  uint y0;           //   the pixels the volume's box (skipping: the active cells' box) can
                     //   project into (engine/raycast.cpp); tile pass: tile of (0, 0)
};
// The hit count of the march pass and, at offset 0, the indirect dispatch of the shade pass
// (VkDispatchIndirectCommand), written by raycast_args.comp; binding 14 is a second one: the
// tiles raycast_tiles.comp listed and the tiled march's dispatch.
struct RaycastCounter {
  uint groups_x;
  uint groups_y;
  uint groups_z;
  uint count;        // pixels appended by raycast_march.comp (rays for raycast_shade.comp to finish)
};
// The floor of a frame on this device (raycast_floor.comp, tests/bench_raycast_floor.cpp):
// one invocation per pixel, rows of ISOTOUCH_RAYCAST_WG_X; push constants.
struct RaycastFloorPush {
  uint width;        // frame size [pixels]
  uint height;
  uint pad0;
  uint pad1;
};
// ---- end raycast ----------------------------------------------------------------------

// ---- sparse chain ---------------------------------
// shaders/sparse_brick.comp, engine/sparse_chain.cpp, CPU reference engine/sparse_cpu.cpp.
// One workgroup per candidate 8^3 brick over its raw region (brick + 1 voxel below, + 2
// above for the gradient of the 9^3 stored samples, + the filters' total radius R per
// axis: sx = 11 + 2 rx ...): the first 1-D filter op reads the raw voxels from the src
// binding, every later op reads the previous op's output in shared memory (two buffers,
// A at 0 and B at buf_b floats, each as large as the largest output written into it; with
// no filter the region is loaded into A). The ops come from the params buffer (
// ISOTOUCH_SPARSE_MAX_OPS uvec4 {axis, radius, kind, weight offset}, then the Gaussian
// weights as float bits), takes the exact (min, max) of the smoothed brick widened by 1
// voxel, and if that straddles tau writes the 9^3 samples (value, gradient [value/m]) of
// the brick to its pool slot. Bindings: 0 raw voxels (float, z-slab), 1 candidate brick
// ids (uint), 2 params, 3 ranges (vec2 per candidate), 4 pool (vec4, 729 per slot).
#define ISOTOUCH_SPARSE_WG 8         // one SIMD vector of lavapipe (256 bits)
#define ISOTOUCH_SPARSE_DEFAULT_GROUPS 64u  // workgroups per dispatch by default (each loops over
                                           // its share; the host raises it for llvmpipe's loop budget)
#define ISOTOUCH_SPARSE_SHARED_FLOATS 7168u  // both shared buffers together (28 KiB)
#define ISOTOUCH_SPARSE_MAX_OPS 16u
#define ISOTOUCH_SPARSE_OP_GAUSS 0u
#define ISOTOUCH_SPARSE_OP_MAX 1u
#define ISOTOUCH_SPARSE_OP_MIN 2u
#define ISOTOUCH_SPARSE_SAMPLES 729u       // 9^3 stored samples per active brick
struct SparseBrickPush {
  uint nx;            // volume size in voxels
  uint ny;
  uint nz;
  uint bx;            // bricks along x: ceil(nx / 8)
  uint by;
  uint src_z0;        // first slice present in the src binding
  uint src_offset;    // elements between the src binding start and slice src_z0
  uint cand_offset;   // candidate index of workgroup 0 of this dispatch
  uint pool_base;     // candidate index stored in slot 0 of the bound pool
  uint sx;            // region size in voxels: 11 + 2 R per axis
  uint sy;
  uint sz;
  uint rx;            // total filter radius R per axis [voxels]
  uint ry;
  uint rz;
  uint n_ops;         // 1-D filter ops in the params buffer
  uint inside_above;  // 1: value > tau is inside (threshold = largest float <= tau);
                      // 0: value < tau is inside (threshold = smallest float >= tau)
  float threshold;    // tau as a float that gives the same comparisons as the double tau
  float background;   // value of the stored samples beyond the grid (gradient 0)
  float inv_2h_x;     // 1 / (2 spacing) [1/m]
  float inv_2h_y;
  float inv_2h_z;
  float inv_h_x;      // 1 / spacing [1/m]
  float inv_h_y;
  float inv_h_z;
  uint buf_b;         // first float of shared buffer B (A starts at 0)
  uint cand_end;      // candidates [cand_offset, cand_end) in this dispatch, strided over the workgroups
  uint groups;        // workgroups in this dispatch (the stride)
};
// ---- end sparse chain -----------------------------------------------------------------

// ---- brushes -----------------------------------------
// shaders/brush.comp, session/brush.cpp, CPU reference session/brush_cpu.cpp; the model is
// documented in session/brush.h. One 8x8x8 workgroup per touched 8^3 brick (a box dispatch
// over the brick box the brush's voxel-space bounding box touches; one dispatch per z-chunk
// of brick layers whose slices fit a binding). Bindings: 0 the raw volume (float, x
// fastest; a window of whole slices starting at linear voxel vol_base), 1 the pre-edit
// copy that smooth reads (float; the touched box + 1 voxel, compact: pre_*; any buffer for
// the other kinds), 2 dirty flags (uint per brick of the whole box, x fastest, zeroed
// before the dispatch; 1 where some voxel's bits changed).
#define ISOTOUCH_BRUSH_WG 8           // 8x8x8 invocations = one 8^3 brick
#define ISOTOUCH_BRUSH_ADD 0u         // move toward `target` (the material value)
#define ISOTOUCH_BRUSH_CARVE 1u       // move toward `target` (the empty value)
#define ISOTOUCH_BRUSH_SMOOTH 2u      // blend toward the 6-neighbour mean of the pre-edit values
#define ISOTOUCH_BRUSH_DRILL 3u       // move toward `target` (empty), slower on denser voxels
struct BrushPush {
  uint nx;              // volume size in voxels
  uint ny;
  uint nz;
  uint kind;            // ISOTOUCH_BRUSH_*
  uint b0x;             // first brick of this dispatch (brick coordinates)
  uint b0y;
  uint b0z;
  uint box_bx;          // bricks of the whole touched box along x (dirty flag index)
  uint box_by;          // ... along y
  uint box_b0z;         // first brick layer of the whole touched box
  uint vol_base;        // linear voxel index at the start of binding 0
  uint src_base;        // elements of the pre-edit box before the start of binding 1
  float cx;             // brush centre, index space [voxels]
  float cy;
  float cz;
  float sx;             // spacing [m]
  float sy;
  float sz;
  float radius;         // brush radius [m]
  float inner;          // weight 1 up to this distance [m]
  float inv_width;      // 1 / (radius - inner) [1/m]
  float amount;         // add/carve/drill: step [value units] at weight 1; smooth: blend fraction
  float target;         // add: material value; carve/drill: empty value [value units]
  float dens_sign;      // drill: +1 if material > empty, else -1
  float inv_dens_scale; // drill: 1 / density scale [1/value units]
  uint pre_x0;          // smooth: binding 1 holds the box [pre_x0, +pre_w) x [pre_y0, +pre_h) x
  uint pre_y0;          //   [pre_z0, ...) of pre-edit voxels (touched box + 1 voxel, clipped),
  uint pre_z0;          //   x fastest; src_base = its elements before the binding start
  uint pre_w;
  uint pre_h;
  uint pad0;
};
// ---- end brushes ----------------------------------------------------------------------

#ifdef __cplusplus
}  // namespace isotouch::gpu
#endif
#endif  // ISOTOUCH_SHARED_H
