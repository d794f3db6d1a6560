// raycast.cpp - the GPU ray caster (shaders/raycast_*.comp: march, args, shade, overlay). The
// field it marches is made in raycast_field.cpp, cameras and overlay primitives in raycast_view.cpp.
#include "isotouch/engine/raycast.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <span>
#include <stdexcept>
#include <tuple>

#include "isotouch/shaders/raycast_args_spv.h"
#include "isotouch/shaders/raycast_floor_spv.h"
#include "isotouch/shaders/raycast_march_count_spv.h"
#include "isotouch/shaders/raycast_march_spv.h"
#include "isotouch/shaders/raycast_overlay_spv.h"
#include "isotouch/shaders/raycast_shade_count_spv.h"
#include "isotouch/shaders/raycast_shade_spv.h"
#include "isotouch/shaders/raycast_tiles_spv.h"
#include "isotouch/engine/raycast_detail.h"
#include "isotouch/engine/vk_resources.h"

namespace isotouch::engine {

// The C++ view of the shared structs (std430: 4-byte scalars, offset = 4 * member index).
static_assert(sizeof(gpu::RaycastParams) == 52 * 4);
static_assert(sizeof(gpu::RaycastParams) % 16 == 0, "binding 0 is std140: its struct size rounds up to 16 bytes");
static_assert(offsetof(gpu::RaycastParams, tau) == 8 * 4);
static_assert(offsetof(gpu::RaycastParams, eye_x) == 12 * 4);
static_assert(offsetof(gpu::RaycastParams, clip_d) == 19 * 4);
static_assert(offsetof(gpu::RaycastParams, origin_x) == 28 * 4);
static_assert(offsetof(gpu::RaycastParams, cap_b) == 43 * 4);
static_assert(offsetof(gpu::RaycastParams, act_hi_z) == 49 * 4);
static_assert(sizeof(gpu::RaycastPrim) == 16 * 4);
static_assert(offsetof(gpu::RaycastPrim, ax) == 4 * 4);
static_assert(offsetof(gpu::RaycastPrim, cr) == 7 * 4);
static_assert(offsetof(gpu::RaycastPrim, cb) == 15 * 4);
static_assert(sizeof(gpu::RaycastPush) == 16);
static_assert(sizeof(gpu::RaycastCounter) == 16);
static_assert(offsetof(gpu::RaycastCounter, groups_x) == 0, "VkDispatchIndirectCommand at offset 0");
static_assert(offsetof(gpu::RaycastCounter, count) == 12);
static_assert(ISOTOUCH_RAYCAST_DIST_MAX >= 1u && ISOTOUCH_RAYCAST_DIST_MAX <= 255u, "cell distances are bytes");
// llvmpipe's budget of 65535 loop iterations per shader invocation (counted per vector of 8
// lanes): the plain march (one flat loop, at most MAX_SAMPLES + 1 trips) and two boxes (3
// each) in the march pass (the skipping march may run out; it says so and the shade pass
// finishes the ray); the finishing plain march, the refinement (6 bisections) and the box in
// the shade pass; the box and the two overlay loops in the overlay pass.
static_assert(ISOTOUCH_RAYCAST_MAX_SAMPLES + 1u + ISOTOUCH_RAYCAST_BISECTIONS < 65535u);
static_assert(ISOTOUCH_RAYCAST_MAX_SAMPLES + 1u + ISOTOUCH_RAYCAST_BISECTIONS + 3u < 65535u);
static_assert(3u + 2u * ISOTOUCH_RAYCAST_MAX_PRIMS < 65535u);
static_assert(ISOTOUCH_RAYCAST_TILE * ISOTOUCH_RAYCAST_TILE == ISOTOUCH_RAYCAST_WG_X, "a tiled march workgroup is one tile");
static_assert(ISOTOUCH_RAYCAST_TILE % ISOTOUCH_RAYCAST_BLOCK == 0u, "a tile is whole blocks");
/// Blocks of pixels per tile (raycast_tiles.comp's block pass: one invocation each).
constexpr std::uint32_t kBlocksPerTile =
    (ISOTOUCH_RAYCAST_TILE / ISOTOUCH_RAYCAST_BLOCK) * (ISOTOUCH_RAYCAST_TILE / ISOTOUCH_RAYCAST_BLOCK);
/// Tiles per workgroup of the block pass (raycast_args.comp sizes its dispatch so): a
/// workgroup of WG_X invocations (on llvmpipe a small workgroup costs about as much as a full one).
constexpr std::uint32_t kTilesPerBlockGroup = ISOTOUCH_RAYCAST_WG_X / kBlocksPerTile;
static_assert(kTilesPerBlockGroup * kBlocksPerTile == ISOTOUCH_RAYCAST_WG_X);
// The tile pass: its cone march and its cone interval (3 trips).
static_assert(ISOTOUCH_RAYCAST_TILE_STEPS + 6u < 65535u);

using namespace raycast_detail;

namespace {
/// n pixels from device memory to RGBA: copied, or with red and blue swapped back.
void copy_pixels(std::uint32_t* dst, const void* src, std::size_t n, bool bgra) {
  if (!bgra) {
    std::memcpy(dst, src, n * 4);
    return;
  }
  const auto* p = static_cast<const std::uint32_t*>(src);
  for (std::size_t i = 0; i < n; ++i) dst[i] = swap_red_blue(p[i]);
}

/// The pixels [x0, x1) x [y0, y1) whose rays can meet the index-space box [lo, hi]: the
/// bounding rectangle of its 8 projected corners, 2 pixels wider for rounding, x0 a multiple
/// of 8; the whole image if a corner is not in front of the eye.
struct PixelRect {
  std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};
PixelRect box_rect(const gpu::RaycastParams& P, std::array<double, 3> lo, std::array<double, 3> hi) {
  const Vec3 eye{P.eye_x, P.eye_y, P.eye_z}, fwd{P.fwd_x, P.fwd_y, P.fwd_z};
  const Vec3 right{P.right_x, P.right_y, P.right_z}, up{P.up_x, P.up_y, P.up_z};
  PixelRect all{0, 0, P.width, P.height};
  double lo_x = 1e300, hi_x = -1e300, lo_y = 1e300, hi_y = -1e300;
  for (int c = 0; c < 8; ++c) {
    const Vec3 idx{c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]};
    const Vec3 q{P.origin_x + idx.x / double(P.inv_sp_x), P.origin_y + idx.y / double(P.inv_sp_y),
                 P.origin_z + idx.z / double(P.inv_sp_z)};
    const Vec3 v = q - eye;
    const double z = dot(v, fwd);
    if (!(z > 1e-9)) return all;
    // The shader's pixel (px, py) looks along fwd * focal + right * sx + up * sy with
    // sx = px + 0.5 - W / 2, sy = H / 2 - (py + 0.5).
    const double px = double(P.focal_px) * dot(v, right) / z + 0.5 * P.width - 0.5;
    const double py = 0.5 * P.height - 0.5 - double(P.focal_px) * dot(v, up) / z;
    lo_x = std::min(lo_x, px);
    hi_x = std::max(hi_x, px);
    lo_y = std::min(lo_y, py);
    hi_y = std::max(hi_y, py);
  }
  auto clampi = [](double v, std::uint32_t n) { return std::uint32_t(std::clamp(v, 0.0, double(n))); };
  PixelRect r;
  r.x0 = clampi(std::floor(lo_x) - 2, P.width) / 8 * 8;  // whole vectors of 8 lanes
  r.y0 = clampi(std::floor(lo_y) - 2, P.height);
  r.x1 = clampi(std::ceil(hi_x) + 3, P.width);
  r.y1 = clampi(std::ceil(hi_y) + 3, P.height);
  if (r.x1 <= r.x0 || r.y1 <= r.y0) r.x1 = r.x0, r.y1 = r.y0;  // the box is off screen
  return r;
}

/// The pixels the primitives' bounding box (index space, 1 voxel wider) projects to (none
/// without primitives; the whole image if one is not finite): a pixel whose ray meets no
/// primitive keeps the colour the shade pass gave it.
PixelRect overlay_rect(const gpu::RaycastParams& P, std::span<const gpu::RaycastPrim> prims, int width, int height) {
  if (prims.empty()) return {};
  std::array<double, 3> plo{1e300, 1e300, 1e300}, phi{-1e300, -1e300, -1e300};
  auto grow = [&](double x, double y, double z, double r) {
    r = std::abs(r);  // the shader draws a primitive of radius |r0|
    const double p[3] = {x, y, z};
    const double inv[3] = {double(P.inv_sp_x), double(P.inv_sp_y), double(P.inv_sp_z)};
    const double org[3] = {double(P.origin_x), double(P.origin_y), double(P.origin_z)};
    for (int a = 0; a < 3; ++a) {
      plo[a] = std::min(plo[a], (p[a] - r - org[a]) * inv[a] - 1.0);
      phi[a] = std::max(phi[a], (p[a] + r - org[a]) * inv[a] + 1.0);
    }
  };
  bool finite = true;
  for (const gpu::RaycastPrim& q : prims) {
    finite = finite && std::isfinite(q.ax) && std::isfinite(q.ay) && std::isfinite(q.az) && std::isfinite(q.r0) &&
             std::isfinite(q.bx) && std::isfinite(q.by) && std::isfinite(q.bz);
    grow(q.ax, q.ay, q.az, q.r0);
    if (q.kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE || q.kind == ISOTOUCH_RAYCAST_PRIM_CONE) grow(q.bx, q.by, q.bz, q.r0);
  }
  return finite ? box_rect(P, plo, phi) : PixelRect{0, 0, std::uint32_t(width), std::uint32_t(height)};
}

/// The pixels in both (empty: x1 = x0, y1 = y0). x0 stays a multiple of 8 if both are.
PixelRect intersect(const PixelRect& a, const PixelRect& b) {
  PixelRect r{std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
  if (r.x1 <= r.x0 || r.y1 <= r.y0) r.x1 = r.x0, r.y1 = r.y0;
  return r;
}

/// The overlay's stages (raycast_overlay.comp, specialization constant 9) and the most list
/// entries drawn in stages, one dispatch each; more are drawn in one pass.
constexpr std::uint32_t kOverlayBegin = 1, kOverlayOpaque = 2, kOverlayBlend = 3, kOverlayEnd = 4;
constexpr std::size_t kMaxOverlayStages = 32;

/// The overlay pass's primitives (binding 3): the ones its opaque loop reads (alpha 1, x-ray
/// ones too), then the ones its blending loop reads (alpha < 1 or x-ray), each list in the
/// caller's order, so each loop reads only its own (on llvmpipe a primitive a loop skips with
/// `continue` costs its whole intersection anyway). An x-ray primitive of alpha 1 is in both.
struct OverlayLists {
  std::vector<gpu::RaycastPrim> prims;
  std::uint32_t opaque = 0;  ///< the first list's length
};
OverlayLists overlay_lists(const std::vector<gpu::RaycastPrim>& prims) {
  OverlayLists l;
  // The shader's own tests, negated as it skips (a NaN alpha: in both, as it was).
  for (const gpu::RaycastPrim& q : prims)
    if (!(q.alpha < 1.0f)) l.prims.push_back(q);
  l.opaque = std::uint32_t(l.prims.size());
  for (const gpu::RaycastPrim& q : prims)
    if (!(q.alpha >= 1.0f && !(q.pad0 > 0.0f))) l.prims.push_back(q);
  return l;
}

/// The index-space box covering every active cell (cell_dist 0; cell c spans [c, c + 1]),
/// or nullopt if there is none. Samples outside it are in inactive cells or outside the
/// cells, where the field is the background: outside, else the border cells were active.
std::optional<std::pair<std::array<double, 3>, std::array<double, 3>>> active_box(const RaycastField& f) {
  const int cx = f.grid.dims[0] + 2, cy = f.grid.dims[1] + 2, cz = f.grid.dims[2] + 2;
  std::array<int, 3> lo{cx, cy, cz}, hi{-1, -1, -1};
  for (int z = 0; z < cz; ++z)
    for (int y = 0; y < cy; ++y)
      for (int x = 0; x < cx; ++x)
        if (f.cell_dist[(std::size_t(z) * std::size_t(cy) + std::size_t(y)) * std::size_t(cx) + std::size_t(x)] == 0) {
          lo = {std::min(lo[0], x), std::min(lo[1], y), std::min(lo[2], z)};
          hi = {std::max(hi[0], x), std::max(hi[1], y), std::max(hi[2], z)};
        }
  if (hi[0] < 0) return std::nullopt;
  // Stored at c + 1: cell c = stored - 1 spans [c, c + 1].
  return std::pair{std::array<double, 3>{lo[0] - 1.0, lo[1] - 1.0, lo[2] - 1.0},
                   std::array<double, 3>{double(hi[0]), double(hi[1]), double(hi[2])}};
}
}  // namespace

/// What one frame draws (RayCaster::render): its parameters and push constants, the pixels
/// the march covers, the primitives' rectangle and the overlay pass's, and whether the frame
/// reuses the last one (see plan_frame).
struct FramePlan {
  gpu::RaycastParams P{};
  gpu::RaycastParams key{};  // P with the active box zeroed: what reuse compares
  gpu::RaycastPush push{};
  PixelRect rect, orect, overlay;
  bool reuse = false;
  bool linear = false;  // the shade pass writes the linear colour (bindings 6-8)
  int band_y0 = -1, band_y1 = -1;  // render_rows: only these rows are cleared and drawn (-1: none)
  int width = 0, height = 0;
  std::size_t pixels = 0, tile_count = 0;
};

struct RayCaster::Impl {
  /// Bindings 1 (values) and 2 (cell distances) are uniform texel buffers.
  /// Binding 12 (quads) is one too, viewed as R32G32B32A32_SFLOAT.
  /// Binding 3 (the primitives) is one too, viewed as R32G32B32A32_UINT (set_views).
  static constexpr std::uint32_t kTexel = (1u << 1) | (1u << 2) | (1u << 3) | (1u << 12);
  static constexpr std::uint32_t kVec4 = 1u << 12;
  /// The texel bindings' views of every raycast pipeline: the quads (and the values with
  /// VALS4) 4 floats per texel, the primitives 4 words per texel.
  void set_views(ComputePipelineBase& p) const {
    p.set_texel_vec4(kVec4 | (vals4 ? 1u << 1 : 0u));
    p.set_texel_uint4(1u << 3);
  }
  VulkanContext& ctx;
  RaycastField field;
  bool use_quads = false;  // binding 12 holds the quads (shaders/raycast_common.glsl)
  bool vals4 = false;      // binding 1 holds 4 voxels per texel (VALS4 in shaders/raycast_common.glsl)
  // The five passes (shaders/raycast_common.glsl), one descriptor layout.
  // march and shade in two variants each (specialization constant 0: skipping; linear colour).
  // tiles and the march from them (march_tiled), with args_tiles for its indirect dispatch.
  // The march shades its hits: the variants that also write the linear colour (constant 8,
  // frames with primitives) are made on the first such frame (linear_marches()).
  /// The march's three forms (tile starts, skipping, plain) of one SPIR-V and linear colour.
  struct Marches {
    ComputePipeline<gpu::RaycastPush> tiled, skip, plain;
    template <std::size_t N>
    Marches(const Impl& m, const std::uint32_t (&spv)[N], bool linear, const std::string& what)
        : tiled(m.ctx, spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast march (tile starts" + what + ")", 1u,
                m.spec(1, true, linear), kTexel),
          skip(m.ctx, spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast march (skipping" + what + ")", 1u,
               m.spec(1, false, linear), kTexel),
          plain(m.ctx, spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast march (no skipping" + what + ")", 1u,
                m.spec(0, false, linear), kTexel) {
      for (auto* p : {&tiled, &skip, &plain}) m.set_views(*p);
    }
    const ComputePipeline<gpu::RaycastPush>& pick(bool tiles, bool skip_empty) const {
      return tiles ? tiled : skip_empty ? skip : plain;
    }
  };
  ComputePipeline<gpu::RaycastPush> tiles, args_tiles, blocks;
  Marches marches;
  ComputePipeline<gpu::RaycastPush> args, shade_lin, shade, overlay;
  std::unique_ptr<Marches> marches_lin;
  GpuBuffer values, cells;                 // device-local, resident (cells: one float per cell)
  GpuBuffer quads;                         // device-local, resident: binding 12 (16 bytes unused without quads)
  GpuBuffer params, prims;                 // device-local, rewritten per frame
  GpuBuffer params_up, prims_up;           // staging
  GpuBuffer counter;                       // RaycastCounter: hit count, indirect dispatch; then the fetch counts
  /// The march and shade pipelines that count their texel fetches (*_count_spv), made on the first
  /// set_count_fetches(true); `counting`: render() draws with them.
  struct Counting {
    Marches march, march_lin;
    ComputePipeline<gpu::RaycastPush> shade_lin, shade;
  };
  std::unique_ptr<Counting> count_pipes;
  bool counting = false;
  // Per pixel, device-local, sized for the last frame: image, depth, linear colour R G B,
  // hit list, hit sample.
  GpuBuffer image, depth, lin_r, lin_g, lin_b, hits, hit_k;
  /// Binding 16: per pixel the overlay stages' colour and nearest depth (vec4); 16 bytes where
  /// one binding cannot hold the frame's (the overlay is then drawn in one pass).
  GpuBuffer overlay_state;
  bool overlay_staged = true;  // set_overlay_stages()
  int overlay_dispatches = 0;  // the frame being recorded's (RaycastImage::overlay_dispatches)
  /// The overlay's stage pipelines (raycast_overlay.comp: constant 9 the stage, 10 the
  /// primitive kind), made on first use: begin, end, then opaque and blend per kind.
  std::array<std::unique_ptr<ComputePipeline<gpu::RaycastPush>>, 2 + 2 * 4> overlay_stages;
  /// Every stage pipeline, made on the first frame drawn in stages (not on the first primitive
  /// of a kind: a disc appears at the first contact, mid-session).
  void make_overlay_stages() {
    overlay_stage(kOverlayBegin, 0);
    overlay_stage(kOverlayEnd, 0);
    for (std::uint32_t k = ISOTOUCH_RAYCAST_PRIM_SPHERE; k <= ISOTOUCH_RAYCAST_PRIM_CONE; ++k) {
      overlay_stage(kOverlayOpaque, k);
      overlay_stage(kOverlayBlend, k);
    }
  }
  const ComputePipeline<gpu::RaycastPush>& overlay_stage(std::uint32_t stage, std::uint32_t kind) {
    const std::size_t at = stage == kOverlayBegin ? 0 : stage == kOverlayEnd ? 1 : 2 + (stage == kOverlayBlend ? 4 : 0) + (kind - 1);
    auto& p = overlay_stages[at];
    if (!p) {
      std::vector<std::uint32_t> sp = spec(0);
      sp.push_back(stage);
      sp.push_back(kind);
      sp.push_back(ISOTOUCH_RAYCAST_TILE);  // workgroup: a tile
      sp.push_back(ISOTOUCH_RAYCAST_TILE);
      p = std::make_unique<ComputePipeline<gpu::RaycastPush>>(
          ctx, raycast_overlay_spv, ISOTOUCH_RAYCAST_BINDINGS,
          "raycast overlay (stage " + std::to_string(stage) + ", kind " + std::to_string(kind) + ")", 1u, sp, kTexel);
      set_views(*p);
    }
    return *p;
  }
  GpuBuffer image_down, depth_down;        // readback
  bool keep_on_device = false;             // set_in_place(): the picture is not copied out
  bool bgra = false;                       // set_bgra(): image packed B, G, R, A
  // Binding 13: per tile of pixels where its rays' march can start, then per listed tile
  // (list order) its blocks' starts; binding 15: the listed tiles.
  GpuBuffer tile_t, tile_list;
  // Two RaycastCounters: listed tiles and the tiled march's dispatch; at offset 16 the
  // block pass's dispatch (raycast_args.comp).
  GpuBuffer tile_counter;
  std::size_t pixels = 0, tile_count = 0;
  bool last_tiles = false;                 // the last frame drew with tile starts
  int last_width = 0, last_height = 0;     // the last frame's size
  double mag = 0;  // the cell distances' margin scale (value_magnitude) as last computed
  /// Index-space box of the active cells (nullopt: none; skipping then marches nothing).
  std::optional<std::pair<std::array<double, 3>, std::array<double, 3>>> active;
  DescriptorArena arena;                   // reset per frame
  GpuTimer timer;
  // The last frame, kept for the next one (RayCaster::render: reuse): its parameters (the
  // active box zeroed: skipping does not change a pixel), flags and whether the linear
  // colour of every hit pixel is in bindings 6-8; the overlay's pixel rectangle; the voxels
  // update() changed since ([lo, hi) index space, lo > hi: none).
  bool cache_valid = false, cache_linear = false;
  gpu::RaycastParams cache_key{};
  std::uint32_t cache_flags = 0;
  PixelRect cache_orect;
  std::array<int, 3> dirty_lo{1, 1, 1}, dirty_hi{0, 0, 0};
  // render_rows: the rows [0, band_next) drawn so far for band_key / band_flags at this size.
  int band_next = 0, last_band_width = 0, last_band_height = 0;
  gpu::RaycastParams band_key{};
  std::uint32_t band_flags = 0;
  /// Specialization constants: 0 the pass's variant, 1-3 the grid's size, 4 quads.
  /// 5: the march's tile starts (one workgroup per listed tile); 6 the tile pass's
  /// workgroup size (tile_spec; the other passes do not read it); 7 VALS4; 8 the march
  /// writes the linear colour of its hits.
  std::vector<std::uint32_t> spec(std::uint32_t variant, bool tiled = false, bool linear = false) const {
    return {variant, std::uint32_t(field.grid.dims[0]), std::uint32_t(field.grid.dims[1]),
            std::uint32_t(field.grid.dims[2]), use_quads ? 1u : 0u, tiled ? 1u : 0u, ISOTOUCH_RAYCAST_WG_X,
            vals4 ? 1u : 0u, linear ? 1u : 0u};
  }
  /// The march pipelines that write the linear colour (made once).
  const Marches& linear_marches() {
    if (!marches_lin) marches_lin = std::make_unique<Marches>(*this, raycast_march_spv, true, ", linear colour");
    return *marches_lin;
  }
  /// The counting pipelines (made once).
  Counting& counting_pipes() {
    if (!count_pipes) {
      VulkanContext& c = ctx;
      const std::uint32_t b = ISOTOUCH_RAYCAST_BINDINGS;
      count_pipes.reset(new Counting{
          Marches(*this, raycast_march_count_spv, false, ", counting"),
          Marches(*this, raycast_march_count_spv, true, ", linear colour, counting"),
          {c, raycast_shade_count_spv, b, "raycast shade (linear colour, counting)", 1u, spec(1), kTexel},
          {c, raycast_shade_count_spv, b, "raycast shade (counting)", 1u, spec(0), kTexel}});
      Counting& k = *count_pipes;
      for (auto* p : {&k.shade_lin, &k.shade}) set_views(*p);
    }
    return *count_pipes;
  }
  /// The tile pass's (5: the block pass; 6: its workgroup size, one tile's blocks for the block pass).
  std::vector<std::uint32_t> tile_spec(bool block_pass) const {
    std::vector<std::uint32_t> s = spec(0, block_pass);
    s[6] = block_pass ? kBlocksPerTile * kTilesPerBlockGroup : ISOTOUCH_RAYCAST_WG_X;
    return s;
  }
  /// The per-pixel and per-tile buffers for a frame of width x height (reallocated when the
  /// size changes; the last frame's picture is waited for first).
  void size_frame(int width, int height);
  /// The frame's parameters, rectangles and reuse decision (nothing recorded).
  FramePlan plan_frame(const CameraView& view, const RaycastStyle& style, int width, int height,
                       const std::vector<gpu::RaycastPrim>& prims) const;
  /// Background fills of the pixels drawn again, and the counters zeroed.
  void record_clear(VkCommandBuffer cmd, const FramePlan& f) const;
  /// The tile-start passes (skipping with tiles); false when the frame does not use them.
  bool record_tiles(VkCommandBuffer cmd, const FramePlan& f, std::initializer_list<BufferRange> ranges);
  void record_march_and_shade(VkCommandBuffer cmd, const FramePlan& f, bool tiles, bool skip_empty,
                              std::initializer_list<BufferRange> ranges);
  void record_overlay(VkCommandBuffer cmd, const FramePlan& f, const OverlayLists& lists,
                      std::initializer_list<BufferRange> ranges);
  /// Barriers (and copies where device memory is not host-visible) for reading the frame
  /// back; true when image and depth are read in place.
  bool record_readback(VkCommandBuffer cmd, std::size_t pixels);
  /// After the frame completed: what the next frame's reuse compares with.
  void remember_frame(const FramePlan& f);
  /// Records, submits and waits for the frame `f` plans; reads it back (RayCaster::render).
  RaycastImage draw(const FramePlan& f, const RaycastStyle& style, const std::vector<gpu::RaycastPrim>& prims,
                    const std::function<void()>& meanwhile);
  Impl(VulkanContext& c, RaycastField f, bool q, bool v4)
      : ctx(c),
        field(std::move(f)),
        use_quads(q),
        vals4(v4),
        tiles(c, raycast_tiles_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast tiles", 1u, tile_spec(false), kTexel),
        args_tiles(c, raycast_args_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast args (tiles)", 1u, {1u, kTilesPerBlockGroup},
                   kTexel),
        blocks(c, raycast_tiles_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast blocks", 1u, tile_spec(true), kTexel),
        marches(*this, raycast_march_spv, false, ""),
        args(c, raycast_args_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast args", 1u, {}, kTexel),
        shade_lin(c, raycast_shade_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast shade (linear colour)", 1u,
                  spec(1), kTexel),
        shade(c, raycast_shade_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast shade", 1u, spec(0), kTexel),
        overlay(c, raycast_overlay_spv, ISOTOUCH_RAYCAST_BINDINGS, "raycast overlay", 1u, spec(0), kTexel),
        arena(c, 7, 7 * ISOTOUCH_RAYCAST_BINDINGS),
        timer(c, 5) {
    for (auto* p : {&tiles, &args_tiles, &blocks, &args, &shade_lin, &shade, &overlay})
      set_views(*p);
  }
};

RayCaster::RayCaster(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RayCaster::~RayCaster() {
  // Submissions by others may still read the picture (image_buffer()).
  if (impl_) vkQueueWaitIdle(impl_->ctx.queue());
}
const RaycastField& RayCaster::field() const { return impl_->field; }
bool RayCaster::quads() const { return impl_->use_quads; }
bool RayCaster::four_voxels_per_texel() const { return impl_->vals4; }

namespace {
/// Binding 2's texels [t0, t1): texel t holds the distances of cells 4t .. 4t + 3 (0 past
/// the last), 6 bits each from the low end, as a float (an integer below 2^24: exact).
std::vector<float> pack_cells(const std::vector<std::uint8_t>& d, std::size_t t0, std::size_t t1) {
  static_assert(ISOTOUCH_RAYCAST_DIST_MAX < 64u, "6 bits per cell");
  std::vector<float> out(t1 - t0);
  for (std::size_t t = t0; t < t1; ++t) {
    std::uint32_t w = 0;
    for (std::size_t j = 0; j < 4 && 4 * t + j < d.size(); ++j) w |= std::uint32_t(d[4 * t + j]) << (6 * j);
    out[t - t0] = float(w);
  }
  return out;
}

/// The most device memory the quads may take (4 floats per cell, next to the voxels' 1):
/// beyond it, the 1-float path alone (a 512^3 volume would need 2.2 GB more).
constexpr std::uint64_t kQuadBudgetBytes = 1ull << 30;

/// Binding 12's texels of the base corners (x0 .. x1 - 1, y, z), each in [-1, n]: the
/// voxels (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1) of plane z, the background outside
/// the grid (shaders/raycast_common.glsl, quad()), 4 floats per texel into `out`.
void quad_row(const RaycastField& f, int x0, int x1, int y, int z, float* out) {
  const auto& n = f.grid.dims;
  auto v = [&](int x, int yy) {
    if (x < 0 || yy < 0 || z < 0 || x >= n[0] || yy >= n[1] || z >= n[2]) return f.background;
    return f.values[(std::size_t(z) * std::size_t(n[1]) + std::size_t(yy)) * std::size_t(n[0]) + std::size_t(x)];
  };
  for (int x = x0; x < x1; ++x, out += 4) {
    out[0] = v(x, y);
    out[1] = v(x + 1, y);
    out[2] = v(x, y + 1);
    out[3] = v(x + 1, y + 1);
  }
}
/// The texel of base corner (x, y, z) (the cells' layout: stored at b + 1, x fastest).
std::size_t quad_index(const std::array<int, 3>& n, int x, int y, int z) {
  return (std::size_t(z + 1) * std::size_t(n[1] + 2) + std::size_t(y + 1)) * std::size_t(n[0] + 2) + std::size_t(x + 1);
}

/// Uploads `bytes` into a new device-local buffer of `bytes` (or `dst_bytes`, if larger;
/// the rest unwritten): copied into it where the host can write it (lavapipe: no second
/// copy of a 600 MiB volume in a staging buffer), else through a staging buffer (one submit).
Result<GpuBuffer> upload(VulkanContext& ctx, const void* data, std::size_t bytes, const std::string& what,
                         std::size_t dst_bytes = 0) {
  auto dst = GpuBuffer::create(ctx, std::max(bytes, dst_bytes), MemoryIntent::DeviceLocal, what);
  if (!dst) return dst;
  if (dst.value->mapped() != nullptr) {  // host-coherent: the next submission sees the writes
    std::memcpy(dst.value->mapped(), data, bytes);
    return dst;
  }
  auto up = GpuBuffer::create(ctx, bytes, MemoryIntent::Upload, what + " staging");
  if (!up) return Result<GpuBuffer>::fail(up.error);
  std::memcpy(up.value->mapped(), data, bytes);
  VkCommandBuffer cmd = ctx.begin_commands();
  record_copy(cmd, *up.value, *dst.value, bytes);
  barrier_transfer_to_compute(cmd);
  ctx.submit_and_wait(cmd);
  return dst;
}
}  // namespace

namespace {
/// The volume's size, "NX x NY x NZ (N voxels, B MiB of floats)", for messages.
std::string volume_size_text(const RaycastField& f) {
  const auto& n = f.grid.dims;
  return std::to_string(n[0]) + " x " + std::to_string(n[1]) + " x " + std::to_string(n[2]) + " (" +
         std::to_string(f.values.size()) + " voxels, " + std::to_string(f.values.size() * 4 >> 20) + " MiB of floats)";
}
}  // namespace

Result<std::unique_ptr<RayCaster>> RayCaster::create(VulkanContext& ctx, RaycastField field, bool quads,
                                                     std::uint64_t max_texels) {
  using R = Result<std::unique_ptr<RayCaster>>;
  const std::size_t vbytes = field.values.size() * sizeof(float);
  const std::array<int, 3> n = field.grid.dims;  // field is moved into the caster below
  const std::size_t cells = std::size_t(n[0] + 2) * std::size_t(n[1] + 2) * std::size_t(n[2] + 2);
  if (vbytes == 0 || vbytes != field.grid.voxel_count() * sizeof(float)) return R::fail("raycast: empty field");
  if (field.cell_dist.size() != cells)
    return R::fail("raycast: " + std::to_string(field.cell_dist.size()) + " cell distances for a grid needing " +
                   std::to_string(cells) + " (build the field with make_raycast_field)");
  const std::uint64_t device_texels = ctx.properties().limits.maxTexelBufferElements;
  if (max_texels == 0 || max_texels > device_texels) max_texels = device_texels;
  // One float per texel where the voxels fit one texel binding, else 4 (VALS4): up to
  // 4 maxTexelBufferElements voxels, in one allocation of at most maxMemoryAllocationSize.
  const bool vals4 = field.values.size() > max_texels;
  const std::uint64_t vbuf_bytes = vals4 ? (std::uint64_t(vbytes) + 15) / 16 * 16 : vbytes;
  const std::uint64_t max_alloc = ctx.max_allocation_bytes();
  if ((vals4 && vbuf_bytes / 16 > max_texels) || (cells + 3) / 4 > max_texels)
    return R::fail("raycast: the volume " + volume_size_text(field) + " exceeds one texel binding of " +
                   std::to_string(max_texels) + " texels (maxTexelBufferElements on " + ctx.info().name +
                   "): at most " + std::to_string(4 * max_texels) + " voxels, 4 per texel");
  if (max_alloc != 0 && vbuf_bytes > max_alloc)
    return R::fail("raycast: the volume " + volume_size_text(field) + " exceeds maxMemoryAllocationSize " +
                   std::to_string(max_alloc) + " bytes on " + ctx.info().name);
  // Quads where they fit one texel binding, one allocation and the budget.
  const std::uint64_t quad_bytes = std::uint64_t(cells) * 16;
  const bool use_quads = quads && cells <= max_texels && quad_bytes <= kQuadBudgetBytes &&
                         (max_alloc == 0 || quad_bytes <= max_alloc);
  auto impl = std::make_unique<Impl>(ctx, std::move(field), use_quads, vals4);
  impl->active = active_box(impl->field);
  impl->mag = value_magnitude(impl->field.values, impl->field.background);
  auto v = upload(ctx, impl->field.values.data(), vbytes, "raycast values", std::size_t(vbuf_bytes));
  if (!v) return R::fail(v.error);
  impl->values = std::move(*v.value);
  // Binding 2: the cell distances as floats (a texel buffer of R32_SFLOAT).
  const std::vector<float> cd = pack_cells(impl->field.cell_dist, 0, (impl->field.cell_dist.size() + 3) / 4);
  auto b = upload(ctx, cd.data(), cd.size() * sizeof(float), "raycast cell distances");
  if (!b) return R::fail(b.error);
  impl->cells = std::move(*b.value);
  if (use_quads) {  // binding 12: every base corner's quad
    std::vector<float> q(std::size_t(quad_bytes / sizeof(float)));
    for (int z = -1; z <= n[2]; ++z)
      for (int y = -1; y <= n[1]; ++y) quad_row(impl->field, -1, n[0] + 1, y, z, q.data() + 4 * quad_index(n, -1, y, z));
    auto qb = upload(ctx, q.data(), q.size() * sizeof(float), "raycast quads");
    if (!qb) return R::fail(qb.error);
    impl->quads = std::move(*qb.value);
  } else {
    auto qb = GpuBuffer::create(ctx, 16, MemoryIntent::DeviceLocal, "raycast quads (unused)");
    if (!qb) return R::fail(qb.error);
    impl->quads = std::move(*qb.value);
  }
  const std::size_t pb = sizeof(gpu::RaycastParams);
  const std::size_t qb = sizeof(gpu::RaycastPrim) * 2 * ISOTOUCH_RAYCAST_MAX_PRIMS;  // the overlay's two lists
  for (auto [buf, bytes, intent, what] :
       {std::tuple{&impl->params, pb, MemoryIntent::DeviceLocal, "raycast params"},
        std::tuple{&impl->params_up, pb, MemoryIntent::Upload, "raycast params staging"},
        std::tuple{&impl->prims, qb, MemoryIntent::DeviceLocal, "raycast primitives"},
        std::tuple{&impl->prims_up, qb, MemoryIntent::Upload, "raycast primitives staging"},
        std::tuple{&impl->counter, 3 * sizeof(gpu::RaycastCounter), MemoryIntent::DeviceLocal, "raycast counter"},
        std::tuple{&impl->tile_counter, 2 * sizeof(gpu::RaycastCounter), MemoryIntent::DeviceLocal, "raycast tile counter"}}) {
    auto r = GpuBuffer::create(ctx, bytes, intent, what);
    if (!r) return R::fail(r.error);
    *buf = std::move(*r.value);
  }
  return R::ok(std::unique_ptr<RayCaster>(new RayCaster(std::move(impl))));
}

void RayCaster::Impl::size_frame(int width, int height) {
  Impl& m = *this;
  const std::size_t n_pixels = std::size_t(width) * std::size_t(height);
  if (n_pixels * 4 > m.ctx.max_binding_bytes()) throw std::invalid_argument("raycast: image too large for one binding");
  if (n_pixels != m.pixels) {
    // Submissions since the last frame may still read the old picture (image_buffer()).
    VK_CHECK(vkQueueWaitIdle(m.ctx.queue()));
    for (auto [buf, what] : {std::pair{&m.image, "raycast image"}, std::pair{&m.depth, "raycast depth"},
                             std::pair{&m.lin_r, "raycast colour R"}, std::pair{&m.lin_g, "raycast colour G"},
                             std::pair{&m.lin_b, "raycast colour B"}, std::pair{&m.hits, "raycast hit list"},
                             std::pair{&m.hit_k, "raycast hit samples"}})
      *buf = make_buffer_or_throw(m.ctx, n_pixels * 4, MemoryIntent::DeviceLocal, what);
    if (!(m.ctx.device_local_is_host_visible() && m.image.mapped() && m.depth.mapped())) {
      m.image_down = make_buffer_or_throw(m.ctx, n_pixels * 4, MemoryIntent::Readback, "raycast image readback");
      m.depth_down = make_buffer_or_throw(m.ctx, n_pixels * 4, MemoryIntent::Readback, "raycast depth readback");
    }
    // The overlay stages' buffer; where it would not fit one binding or cannot be had, 16
    // bytes (the overlay is then drawn in one pass).
    m.overlay_state = {};
    if (n_pixels * 16 <= m.ctx.max_binding_bytes()) {
      try {
        m.overlay_state = make_buffer_or_throw(m.ctx, n_pixels * 16, MemoryIntent::DeviceLocal, "raycast overlay state");
      } catch (const std::exception&) {
      }
    }
    if (!m.overlay_state.handle())
      m.overlay_state = make_buffer_or_throw(m.ctx, 16, MemoryIntent::DeviceLocal, "raycast overlay state");
    m.pixels = n_pixels;
    m.cache_valid = false;
    m.last_width = m.last_height = 0;  // no frame in the new buffers until this one completes
  }
  const std::uint32_t tiles_x = (std::uint32_t(width) + ISOTOUCH_RAYCAST_TILE - 1) / ISOTOUCH_RAYCAST_TILE;
  const std::uint32_t tiles_y = (std::uint32_t(height) + ISOTOUCH_RAYCAST_TILE - 1) / ISOTOUCH_RAYCAST_TILE;
  const std::size_t n_tiles = std::size_t(tiles_x) * tiles_y;
  if (n_tiles != m.tile_count) {
    m.tile_t = make_buffer_or_throw(m.ctx, n_tiles * (1 + kBlocksPerTile) * 4, MemoryIntent::DeviceLocal,
                                    "raycast tile and block starts");
    m.tile_list = make_buffer_or_throw(m.ctx, n_tiles * 4, MemoryIntent::DeviceLocal, "raycast tile list");
    m.tile_count = n_tiles;
  }
}

FramePlan RayCaster::Impl::plan_frame(const CameraView& view, const RaycastStyle& style, int width, int height,
                                           const std::vector<gpu::RaycastPrim>& frame_prims) const {
  const Impl& m = *this;
  FramePlan f;
  f.width = width;
  f.height = height;
  f.pixels = m.pixels;
  f.tile_count = m.tile_count;
  gpu::RaycastParams& P = f.P;
  P = make_params(m.field, view, style, width, height);
  if (m.active) {  // the skipping march starts and ends at the active cells' box, widened by
    // 1/16 voxel: a ray grazing its face must not round to "misses the box"
    const auto& [lo, hi] = *m.active;
    set3(P.act_lo_x, P.act_lo_y, P.act_lo_z, {lo[0] - 0.0625, lo[1] - 0.0625, lo[2] - 0.0625});
    set3(P.act_hi_x, P.act_hi_y, P.act_hi_z, {hi[0] + 0.0625, hi[1] + 0.0625, hi[2] + 0.0625});
  }
  f.push.flags = style_flags(style) | (m.bgra ? ISOTOUCH_RAYCAST_BGRA : 0u);
  f.push.prim_count = std::uint32_t(frame_prims.size());
  // The march covers only where the volume's box (skipping: the active cells' box) projects.
  if (!style.skip_empty)
    f.rect = box_rect(P, {-1, -1, -1}, {double(P.nx), double(P.ny), double(P.nz)});
  else if (m.active)
    f.rect = box_rect(P, m.active->first, m.active->second);
  // Reuse: the same camera, style and size as the last frame: only the pixels whose rays
  // can meet the voxels update() changed are marched and shaded again (within 3 voxels of
  // them: the trilinear cells, the refinement's block and the normal's neighbours), and the
  // overlay is redrawn over its old and new rectangles; every other pixel stays as it was,
  // which is what a full frame would draw there.
  f.key = P;
  set3(f.key.act_lo_x, f.key.act_lo_y, f.key.act_lo_z, {0, 0, 0});
  set3(f.key.act_hi_x, f.key.act_hi_y, f.key.act_hi_z, {0, 0, 0});
  f.orect = overlay_rect(P, frame_prims, width, height);
  const bool needs_linear = f.orect.x1 > f.orect.x0 || m.cache_orect.x1 > m.cache_orect.x0;
  f.reuse = m.cache_valid && m.cache_flags == f.push.flags && std::memcmp(&f.key, &m.cache_key, sizeof f.key) == 0 &&
            (!needs_linear || m.cache_linear);
  if (f.reuse) {
    PixelRect d;
    if (m.dirty_lo[0] < m.dirty_hi[0])
      d = box_rect(P, {m.dirty_lo[0] - 3.0, m.dirty_lo[1] - 3.0, m.dirty_lo[2] - 3.0},
                   {m.dirty_hi[0] + 2.0, m.dirty_hi[1] + 2.0, m.dirty_hi[2] + 2.0});
    PixelRect& r = f.rect;
    r = {std::max(r.x0, d.x0), std::max(r.y0, d.y0), std::min(r.x1, d.x1), std::min(r.y1, d.y1)};
    if (r.x1 <= r.x0 || r.y1 <= r.y0) r = PixelRect{};
  }
  f.linear = f.reuse ? m.cache_linear : !frame_prims.empty();  // bindings 6-8 complete after this frame
  // The overlay over the primitives' rectangle and, reusing, the last frame's (there it
  // draws the picture without them again, from the linear colour).
  f.overlay = f.orect;
  if (f.reuse && m.cache_orect.x1 > m.cache_orect.x0) {
    const PixelRect& c = m.cache_orect;
    PixelRect& od = f.overlay;
    od = od.x1 > od.x0 ? PixelRect{std::min(od.x0, c.x0), std::min(od.y0, c.y0), std::max(od.x1, c.x1), std::max(od.y1, c.y1)} : c;
  }
  return f;
}

void RayCaster::Impl::record_clear(VkCommandBuffer cmd, const FramePlan& f) const {
  const Impl& m = *this;
  // Every pixel starts as background (colour, depth -1): the march pass writes hits only.
  vkCmdFillBuffer(cmd, m.counter.handle(), 0, VK_WHOLE_SIZE, 0);       // hit count 0
  vkCmdFillBuffer(cmd, m.tile_counter.handle(), 0, VK_WHOLE_SIZE, 0);  // tile count 0
  if (f.push.flags & ISOTOUCH_RAYCAST_TILES)  // tiles the tile pass does not reach: +inf
    vkCmdFillBuffer(cmd, m.tile_t.handle(), 0, f.tile_count * 4, std::bit_cast<std::uint32_t>(std::numeric_limits<float>::infinity()));
  std::uint32_t bg = pack_rgba8(f.P.bg_r, f.P.bg_g, f.P.bg_b);
  if (m.bgra) bg = swap_red_blue(bg);
  const std::uint32_t no_hit = std::bit_cast<std::uint32_t>(-1.0f);
  if (f.band_y0 >= 0) {  // the band's rows whole: what they held was another frame's
    const VkDeviceSize at = VkDeviceSize(f.band_y0) * std::uint32_t(f.width) * 4,
                       n = VkDeviceSize(f.band_y1 - f.band_y0) * std::uint32_t(f.width) * 4;
    if (n > 0) {
      vkCmdFillBuffer(cmd, m.image.handle(), at, n, bg);
      vkCmdFillBuffer(cmd, m.depth.handle(), at, n, no_hit);
    }
    return;
  }
  if (!f.reuse) {
    vkCmdFillBuffer(cmd, m.image.handle(), 0, f.pixels * 4, bg);
    vkCmdFillBuffer(cmd, m.depth.handle(), 0, f.pixels * 4, no_hit);
    return;
  }
  const PixelRect& r = f.rect;
  for (std::uint32_t y = r.y0; y < r.y1; ++y) {  // the rows of the region drawn again
    const VkDeviceSize at = (VkDeviceSize(y) * std::uint32_t(f.width) + r.x0) * 4, n = VkDeviceSize(r.x1 - r.x0) * 4;
    vkCmdFillBuffer(cmd, m.image.handle(), at, n, bg);
    vkCmdFillBuffer(cmd, m.depth.handle(), at, n, no_hit);
  }
}

bool RayCaster::Impl::record_tiles(VkCommandBuffer cmd, const FramePlan& f, std::initializer_list<BufferRange> ranges) {
  Impl& m = *this;
  const PixelRect& rect = f.rect;
  if ((f.push.flags & ISOTOUCH_RAYCAST_TILES) == 0u || rect.x1 <= rect.x0) return false;
  // The tiles holding the march's pixels.
  const std::uint32_t T = ISOTOUCH_RAYCAST_TILE;
  gpu::RaycastPush tile_push = f.push;
  tile_push.x0 = rect.x0 / T;
  tile_push.y0 = rect.y0 / T;
  const std::uint32_t nx = (rect.x1 + T - 1) / T - tile_push.x0, ny = (rect.y1 + T - 1) / T - tile_push.y0;
  m.tiles.bind(cmd, m.arena, ranges);
  m.tiles.push(cmd, tile_push);
  vkCmdDispatch(cmd, (nx + ISOTOUCH_RAYCAST_WG_X - 1) / ISOTOUCH_RAYCAST_WG_X, ny, 1);
  barrier_compute_to_compute(cmd);
  m.args_tiles.bind(cmd, m.arena, ranges);
  m.args_tiles.push(cmd, f.push);
  vkCmdDispatch(cmd, 1, 1, 1);
  barrier_compute_to_indirect(cmd);
  m.blocks.bind(cmd, m.arena, ranges);  // the listed tiles' blocks: kTilesPerBlockGroup tiles per workgroup
  m.blocks.push(cmd, f.push);
  vkCmdDispatchIndirect(cmd, m.tile_counter.handle(), sizeof(gpu::RaycastCounter));
  barrier_compute_to_compute(cmd);
  return true;
}

void RayCaster::Impl::record_march_and_shade(VkCommandBuffer cmd, const FramePlan& f, bool tiled, bool skip_empty,
                                       std::initializer_list<BufferRange> ranges) {
  Impl& m = *this;
  const PixelRect& rect = f.rect;
  gpu::RaycastPush march_push = f.push;
  march_push.x0 = rect.x0;
  march_push.y0 = rect.y0;
  // The march: over the listed tiles (tile starts; a listed tile partly outside `rect` when
  // reusing draws its pixels outside as a full frame would, i.e. as they are), else `rect`.
  Counting* k = m.counting ? &m.counting_pipes() : nullptr;
  const Marches& forms = k ? (f.linear ? k->march_lin : k->march) : f.linear ? m.linear_marches() : m.marches;
  const auto& march = forms.pick(tiled, skip_empty);
  march.bind(cmd, m.arena, ranges);
  march.push(cmd, march_push);
  if (tiled)
    vkCmdDispatchIndirect(cmd, m.tile_counter.handle(), 0);
  else if (rect.x1 > rect.x0)
    vkCmdDispatch(cmd, (rect.x1 - rect.x0 + ISOTOUCH_RAYCAST_WG_X - 1) / ISOTOUCH_RAYCAST_WG_X,
                  (rect.y1 - rect.y0 + ISOTOUCH_RAYCAST_WG_Y - 1) / ISOTOUCH_RAYCAST_WG_Y, 1);
  m.timer.mark(cmd, 2);
  barrier_compute_to_compute(cmd);
  m.args.bind(cmd, m.arena, ranges);
  m.args.push(cmd, f.push);
  vkCmdDispatch(cmd, 1, 1, 1);
  barrier_compute_to_indirect(cmd);
  const auto& shade_pass = f.linear ? (k ? k->shade_lin : m.shade_lin) : (k ? k->shade : m.shade);
  shade_pass.bind(cmd, m.arena, ranges);
  shade_pass.push(cmd, f.push);
  vkCmdDispatchIndirect(cmd, m.counter.handle(), 0);
}

void RayCaster::Impl::record_overlay(VkCommandBuffer cmd, const FramePlan& f, const OverlayLists& lists,
                                     std::initializer_list<BufferRange> ranges) {
  Impl& m = *this;
  const PixelRect& od = f.overlay;
  if (od.x1 <= od.x0) return;
  // The one pass in rows of WG_X pixels, the stages in tiles (raycast_overlay.comp).
  const auto dispatch = [&](const ComputePipeline<gpu::RaycastPush>& p, const PixelRect& r, std::uint32_t prim_word) {
    gpu::RaycastPush push = f.push;
    push.x0 = r.x0;
    push.y0 = r.y0;
    push.prim_count = prim_word;
    p.push(cmd, push);
    const bool in_tiles = &p != &m.overlay;
    const std::uint32_t gx = in_tiles ? ISOTOUCH_RAYCAST_TILE : ISOTOUCH_RAYCAST_WG_X;
    const std::uint32_t gy = in_tiles ? ISOTOUCH_RAYCAST_TILE : ISOTOUCH_RAYCAST_WG_Y;
    vkCmdDispatch(cmd, (r.x1 - r.x0 + gx - 1) / gx, (r.y1 - r.y0 + gy - 1) / gy, 1);
  };
  const std::size_t n = lists.prims.size();
  barrier_compute_to_compute(cmd);
  if (!m.overlay_staged || n > kMaxOverlayStages || m.overlay_state.size() < m.pixels * 16) {
    m.overlay.bind(cmd, m.arena, ranges);
    dispatch(m.overlay, od, lists.opaque << 16 | std::uint32_t(n));
    m.overlay_dispatches = 1;
    return;
  }
  m.make_overlay_stages();
  // Stages: one descriptor set for all (their pipeline layouts are defined alike, so the set
  // bound with the first stays bound), a barrier between stages (each reads what the last wrote).
  const auto& begin = m.overlay_stage(kOverlayBegin, 0);
  begin.bind(cmd, m.arena, ranges);
  dispatch(begin, od, 0);
  m.overlay_dispatches = 2;  // BEGIN and END
  for (std::size_t i = 0; i < n; ++i) {
    const gpu::RaycastPrim& q = lists.prims[i];
    if (q.kind < ISOTOUCH_RAYCAST_PRIM_SPHERE || q.kind > ISOTOUCH_RAYCAST_PRIM_CONE) continue;  // misses every ray
    PixelRect r = intersect(overlay_rect(f.P, std::span(&q, 1), f.width, f.height), od);
    if (r.x1 <= r.x0) continue;  // off the rectangle: misses every pixel drawn
    // On BEGIN's grid of tiles (x0 is a multiple of 8 in both): every tile a stage runs is one
    // BEGIN initialised and END packs.
    r.y0 = od.y0 + (r.y0 - od.y0) / ISOTOUCH_RAYCAST_TILE * ISOTOUCH_RAYCAST_TILE;
    barrier_compute_to_compute(cmd);
    const auto& p = m.overlay_stage(i < lists.opaque ? kOverlayOpaque : kOverlayBlend, q.kind);
    p.bind_keeping_set(cmd);
    dispatch(p, r, std::uint32_t(i));
    ++m.overlay_dispatches;
  }
  barrier_compute_to_compute(cmd);
  const auto& end = m.overlay_stage(kOverlayEnd, 0);
  end.bind_keeping_set(cmd);
  dispatch(end, od, 0);
}

bool RayCaster::Impl::record_readback(VkCommandBuffer cmd, std::size_t n_pixels) {
  Impl& m = *this;
  // Where device-local memory is host-visible (lavapipe), image and depth are read in place.
  // Kept on the device: the picture for later transfers (a window's copy), the depth for the host.
  const bool in_place = m.ctx.device_local_is_host_visible() && m.image.mapped() && m.depth.mapped();
  if (in_place) {
    barrier_compute_to_host(cmd);
    if (m.keep_on_device) barrier_compute_to_transfer(cmd);
  } else {
    barrier_compute_to_transfer(cmd);
    if (!m.keep_on_device) record_copy(cmd, m.image, m.image_down, n_pixels * 4);
    record_copy(cmd, m.depth, m.depth_down, n_pixels * 4);
    barrier_transfer_to_host(cmd);
  }
  return in_place;
}

void RayCaster::Impl::remember_frame(const FramePlan& f) {
  Impl& m = *this;
  m.cache_valid = true;
  m.cache_linear = f.linear;
  m.cache_key = f.key;
  m.cache_flags = f.push.flags;
  m.cache_orect = f.orect;
  m.last_tiles = (f.push.flags & ISOTOUCH_RAYCAST_TILES) != 0u;
  m.last_width = f.width;
  m.last_height = f.height;
  m.dirty_lo = {1, 1, 1};
  m.dirty_hi = {0, 0, 0};
}

RaycastImage RayCaster::render(const CameraView& view, const RaycastStyle& style, int width, int height,
                               const std::vector<gpu::RaycastPrim>& prims, const std::function<void()>& meanwhile) {
  Impl& m = *impl_;
  if (prims.size() > ISOTOUCH_RAYCAST_MAX_PRIMS)
    throw std::invalid_argument("raycast: " + std::to_string(prims.size()) + " primitives, at most " +
                                std::to_string(ISOTOUCH_RAYCAST_MAX_PRIMS));
  m.size_frame(width, height);
  const FramePlan f = m.plan_frame(view, style, width, height, prims);
  m.band_next = 0;  // a whole frame ends any bands drawn so far (render_rows)
  return m.draw(f, style, prims, meanwhile);
}

RaycastImage RayCaster::render_rows(const CameraView& view, const RaycastStyle& style, int width, int height, int y0,
                                    int y1) {
  Impl& m = *impl_;
  if (y0 < 0 || y1 <= y0 || y1 > height)
    throw std::invalid_argument("raycast: render_rows: rows [" + std::to_string(y0) + ", " + std::to_string(y1) +
                                ") outside the picture's " + std::to_string(height));
  m.size_frame(width, height);
  FramePlan f = m.plan_frame(view, style, width, height, {});
  // Only the band's rows: cleared whole, marched where the box projects; no overlay. The
  // linear colour too (bindings 6-8): a render() with primitives after the last band draws
  // them over it and reuses the rest of the bands' picture.
  f.reuse = false;
  f.linear = true;
  f.band_y0 = y0;
  f.band_y1 = y1;
  PixelRect& r = f.rect;
  r.y0 = std::max(r.y0, std::uint32_t(y0));
  r.y1 = std::min(r.y1, std::uint32_t(y1));
  if (r.x1 <= r.x0 || r.y1 <= r.y0) r = PixelRect{};
  f.orect = f.overlay = PixelRect{};
  // The bands so far continue only from the last one, for the same parameters and size.
  const bool continues = y0 == m.band_next && y0 > 0 && m.band_flags == f.push.flags &&
                         std::memcmp(&m.band_key, &f.key, sizeof f.key) == 0 && m.last_band_width == width &&
                         m.last_band_height == height;
  if (!continues && y0 != 0) m.band_next = 0;
  if (y0 == 0 || continues) m.band_next = y1;
  m.band_key = f.key;
  m.band_flags = f.push.flags;
  m.last_band_width = width;
  m.last_band_height = height;
  return m.draw(f, style, {}, {});
}

RaycastImage RayCaster::Impl::draw(const FramePlan& f, const RaycastStyle& style,
                                   const std::vector<gpu::RaycastPrim>& frame_prims, const std::function<void()>& meanwhile) {
  Impl& m = *this;
  const int width = f.width, height = f.height;
  const std::size_t n_px = f.pixels, n_tiles = f.tile_count;
  std::memcpy(m.params_up.mapped(), &f.P, sizeof(f.P));
  const OverlayLists lists = overlay_lists(frame_prims);
  if (!lists.prims.empty())
    std::memcpy(m.prims_up.mapped(), lists.prims.data(), lists.prims.size() * sizeof(gpu::RaycastPrim));

  m.arena.reset();  // the previous frame's submission has completed (submit_and_wait)
  VkCommandBuffer cmd = m.ctx.begin_commands();
  // The last frame's picture may still be read by transfers submitted since (a window's copy
  // into its swapchain image): nothing here writes before they are done.
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                       0, 0, nullptr, 0, nullptr, 0, nullptr);
  m.timer.record_reset(cmd);
  record_copy(cmd, m.params_up, m.params, sizeof(f.P));
  if (!lists.prims.empty()) record_copy(cmd, m.prims_up, m.prims, lists.prims.size() * sizeof(gpu::RaycastPrim));
  const std::initializer_list<BufferRange> ranges = {
      {m.params.handle(), 0, m.params.size()}, {m.values.handle(), 0, m.values.size()},
      {m.cells.handle(), 0, m.cells.size()},   {m.prims.handle(), 0, m.prims.size()},
      {m.image.handle(), 0, n_px * 4},         {m.depth.handle(), 0, n_px * 4},
      {m.lin_r.handle(), 0, n_px * 4},         {m.lin_g.handle(), 0, n_px * 4},
      {m.lin_b.handle(), 0, n_px * 4},         {m.hits.handle(), 0, n_px * 4},
      {m.hit_k.handle(), 0, n_px * 4},         {m.counter.handle(), 0, m.counter.size()},
      {m.quads.handle(), 0, m.quads.size()},   {m.tile_t.handle(), 0, n_tiles * (1 + kBlocksPerTile) * 4},
      {m.tile_counter.handle(), 0, m.tile_counter.size()}, {m.tile_list.handle(), 0, n_tiles * 4},
      {m.overlay_state.handle(), 0, m.overlay_state.size()}};
  m.timer.mark(cmd, 0);
  m.record_clear(cmd, f);
  barrier_transfer_to_compute(cmd);
  // 0. tile starts (skipping); 1. march every pixel; 2. hit count -> dispatch size; 3. shade
  // the hits; 4. overlays.
  const bool tiled = m.record_tiles(cmd, f, ranges);
  m.timer.mark(cmd, 4);
  m.record_march_and_shade(cmd, f, tiled, style.skip_empty, ranges);
  m.timer.mark(cmd, 3);
  m.overlay_dispatches = 0;
  m.record_overlay(cmd, f, lists, ranges);
  m.timer.mark(cmd, 1);
  const bool in_place = m.record_readback(cmd, n_px);

  RaycastImage img;
  img.width = width;
  img.height = height;
  img.reused = f.reuse;
  try {
    img.submit_wall_ms = m.ctx.submit_and_wait(cmd, meanwhile);
  } catch (...) {
    m.cache_valid = false;  // what the buffers hold is not the last remembered frame's: draw the next whole
    throw;
  }
  if (f.band_y0 < 0) {
    m.remember_frame(f);
  } else if (m.band_next == height) {  // the bands cover the picture: it is the frame render() draws
    const std::array<int, 3> lo = m.dirty_lo, hi = m.dirty_hi;  // changed while the bands were drawn:
    m.remember_frame(f);                                         // the next frame draws them again
    m.dirty_lo = lo, m.dirty_hi = hi;
    m.band_next = 0;
  } else {
    m.cache_valid = false;  // a part of a picture: the next render() draws whole
  }
  img.gpu_ms = m.timer.elapsed_ms(0, 1);
  img.march_ms = m.timer.elapsed_ms(0, 2);
  img.tiles_ms = m.timer.elapsed_ms(0, 4);
  img.shade_ms = m.timer.elapsed_ms(2, 3);
  img.overlay_ms = m.timer.elapsed_ms(3, 1);
  img.overlay_dispatches = m.overlay_dispatches;
  if (m.keep_on_device) return img;
  // A band's image holds its rows only (the host copy of a whole picture per band would be
  // most of a band's cost at a large window).
  const std::size_t first = f.band_y0 < 0 ? 0 : std::size_t(f.band_y0) * std::size_t(width);
  const std::size_t count = f.band_y0 < 0 ? n_px : std::size_t(f.band_y1 - f.band_y0) * std::size_t(width);
  if (f.band_y0 >= 0) img.height = f.band_y1 - f.band_y0;
  img.rgba.resize(count);
  img.depth.resize(count);
  const auto* rgba = static_cast<const std::uint32_t*>(in_place ? m.image.mapped() : m.image_down.mapped());
  const auto* depths = static_cast<const float*>(in_place ? m.depth.mapped() : m.depth_down.mapped());
  copy_pixels(img.rgba.data(), rgba + first, count, m.bgra);
  std::memcpy(img.depth.data(), depths + first, count * 4);
  return img;
}

void RayCaster::set_in_place(bool on) { impl_->keep_on_device = on; }

void RayCaster::set_overlay_stages(bool on) {
  impl_->overlay_staged = on;
  impl_->cache_valid = false;  // the next frame is drawn whole
}

void RayCaster::set_count_fetches(bool on) {
  impl_->counting = on;
  impl_->cache_valid = false;  // the next frame is drawn whole
}

RayCaster::FetchCount RayCaster::last_fetches() {
  Impl& m = *impl_;
  GpuBuffer down = make_buffer_or_throw(m.ctx, m.counter.size(), MemoryIntent::Readback, "raycast counter readback");
  VkCommandBuffer cmd = m.ctx.begin_commands();
  record_copy(cmd, m.counter, down, m.counter.size());
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  std::uint32_t w[9];
  std::memcpy(w, down.mapped(), sizeof w);
  FetchCount c;
  c.listed = w[3];
  c.pixels = std::uint64_t(m.last_width) * std::uint64_t(m.last_height);
  if (m.counting) {
    c.march = w[4];
    c.shade = w[5];
    c.march_lanes = w[6];
    c.shade_lanes = w[7];
    c.hits = w[8];
  }
  return c;
}
void RayCaster::set_bgra(bool on) { impl_->bgra = on; }
VkBuffer RayCaster::image_buffer() const { return impl_->image.handle(); }
const std::uint32_t* RayCaster::mapped_image() const {
  const Impl& m = *impl_;
  const bool in_place = m.ctx.device_local_is_host_visible() && m.image.mapped() && m.depth.mapped();
  return in_place ? static_cast<const std::uint32_t*>(m.image.mapped()) : nullptr;
}

std::vector<std::uint32_t> RayCaster::last_rgba() {
  Impl& m = *impl_;
  const std::size_t pixels = std::size_t(m.last_width) * std::size_t(m.last_height);
  std::vector<std::uint32_t> out(pixels);
  if (pixels == 0) return out;
  if (m.ctx.device_local_is_host_visible() && m.image.mapped()) {
    copy_pixels(out.data(), m.image.mapped(), pixels, (m.cache_flags & ISOTOUCH_RAYCAST_BGRA) != 0);
    return out;
  }
  GpuBuffer down = make_buffer_or_throw(m.ctx, pixels * 4, MemoryIntent::Readback, "raycast picture readback");
  VkCommandBuffer cmd = m.ctx.begin_commands();
  barrier_compute_to_transfer(cmd);
  record_copy(cmd, m.image, down, pixels * 4);
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  copy_pixels(out.data(), down.mapped(), pixels, (m.cache_flags & ISOTOUCH_RAYCAST_BGRA) != 0);
  return out;
}

float RayCaster::last_depth(int x, int y) {
  Impl& m = *impl_;
  if (x < 0 || y < 0 || x >= m.last_width || y >= m.last_height)
    throw std::out_of_range("raycast: pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the last frame");
  const bool in_place = m.ctx.device_local_is_host_visible() && m.depth.mapped();
  const auto* d = static_cast<const float*>(in_place ? m.depth.mapped() : m.depth_down.mapped());
  return d[std::size_t(y) * std::size_t(m.last_width) + std::size_t(x)];
}

std::vector<float> RayCaster::last_tile_starts() {
  Impl& m = *impl_;
  if (!m.last_tiles) return {};
  GpuBuffer down = make_buffer_or_throw(m.ctx, m.tile_count * 4, MemoryIntent::Readback, "raycast tile starts readback");
  VkCommandBuffer cmd = m.ctx.begin_commands();
  record_copy(cmd, m.tile_t, down, m.tile_count * 4);
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  std::vector<float> out(m.tile_count);
  std::memcpy(out.data(), down.mapped(), m.tile_count * 4);
  return out;
}

std::vector<float> RayCaster::last_block_starts() {
  Impl& m = *impl_;
  if (!m.last_tiles) return {};
  const std::size_t T = ISOTOUCH_RAYCAST_TILE, B = ISOTOUCH_RAYCAST_BLOCK, side = T / B;
  const std::size_t tiles_x = (m.last_width + T - 1) / T, blocks_x = (m.last_width + B - 1) / B;
  const std::size_t blocks_y = (m.last_height + B - 1) / B;
  const std::size_t t_bytes = m.tile_count * (1 + kBlocksPerTile) * 4, l_bytes = m.tile_count * 4;
  GpuBuffer down = make_buffer_or_throw(m.ctx, t_bytes + l_bytes + sizeof(gpu::RaycastCounter), MemoryIntent::Readback,
                                        "raycast block starts readback");
  VkCommandBuffer cmd = m.ctx.begin_commands();
  const VkBufferCopy regions[3] = {{0, 0, t_bytes}, {0, t_bytes, l_bytes}, {0, t_bytes + l_bytes, sizeof(gpu::RaycastCounter)}};
  vkCmdCopyBuffer(cmd, m.tile_t.handle(), down.handle(), 1, &regions[0]);
  vkCmdCopyBuffer(cmd, m.tile_list.handle(), down.handle(), 1, &regions[1]);
  vkCmdCopyBuffer(cmd, m.tile_counter.handle(), down.handle(), 1, &regions[2]);
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  const auto* bytes = static_cast<const std::uint8_t*>(down.mapped());
  gpu::RaycastCounter ctr;
  std::memcpy(&ctr, bytes + t_bytes + l_bytes, sizeof ctr);
  std::vector<float> starts(m.tile_count * (1 + kBlocksPerTile));
  std::vector<std::uint32_t> list(m.tile_count);
  std::memcpy(starts.data(), bytes, t_bytes);
  std::memcpy(list.data(), bytes + t_bytes, l_bytes);
  std::vector<float> out(blocks_x * blocks_y, std::numeric_limits<float>::infinity());
  for (std::size_t j = 0; j < std::min<std::size_t>(ctr.count, m.tile_count); ++j) {
    const std::size_t tx = list[j] & 0xffffu, ty = list[j] >> 16;
    if (ty * tiles_x + tx >= m.tile_count) continue;
    for (std::size_t i = 0; i < kBlocksPerTile; ++i) {
      const std::size_t bx = tx * side + i % side, by = ty * side + i / side;
      if (bx < blocks_x && by < blocks_y) out[by * blocks_x + bx] = starts[m.tile_count + j * kBlocksPerTile + i];
    }
  }
  return out;
}

RayCaster::UpdateStats RayCaster::update(const std::vector<float>& values, const std::vector<std::uint32_t>& bricks) {
  Impl& m = *impl_;
  const auto t0 = std::chrono::steady_clock::now();
  RaycastField& f = m.field;
  if (values.size() != f.values.size())
    throw std::invalid_argument("raycast update: " + std::to_string(values.size()) + " values for a grid of " +
                                std::to_string(f.values.size()) + " voxels");
  const auto& n = f.grid.dims;
  const std::array<std::uint32_t, 3> nb{std::uint32_t((n[0] + 7) / 8), std::uint32_t((n[1] + 7) / 8),
                                        std::uint32_t((n[2] + 7) / 8)};
  const std::uint64_t brick_count = std::uint64_t(nb[0]) * nb[1] * nb[2];
  std::vector<std::uint32_t> ids(bricks);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  UpdateStats st;
  // Voxel rows of the bricks: host copy, then one copy region per row.
  std::vector<VkBufferCopy> regions;
  bool max_changed = false;  // a voxel holding the largest |value| was overwritten
  double new_max = 0;        // the largest finite |value| written
  for (std::uint32_t id : ids) {
    if (id >= brick_count)
      throw std::invalid_argument("raycast update: brick id " + std::to_string(id) + " out of range (the grid has " +
                                  std::to_string(brick_count) + " bricks)");
    const int bx = int(id % nb[0]), by = int(id / nb[0] % nb[1]), bz = int(id / (std::uint64_t(nb[0]) * nb[1]));
    const int x0 = 8 * bx, x1 = std::min(n[0], x0 + 8);
    for (int z = 8 * bz; z < std::min(n[2], 8 * bz + 8); ++z)
      for (int y = 8 * by; y < std::min(n[1], 8 * by + 8); ++y) {
        const std::size_t at = (std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(x0);
        for (std::size_t k = at; k < at + std::size_t(x1 - x0); ++k) {  // the largest |value|: old and new
          if (std::isfinite(f.values[k]) && std::fabs(double(f.values[k])) >= m.mag) max_changed = true;
          if (std::isfinite(values[k])) new_max = std::max(new_max, std::fabs(double(values[k])));
        }
        std::memcpy(f.values.data() + at, values.data() + at, std::size_t(x1 - x0) * sizeof(float));
        regions.push_back({at * sizeof(float), at * sizeof(float), std::size_t(x1 - x0) * sizeof(float)});
      }
  }
  st.bricks = ids.size();
  // The cell distances of the new values, recomputed only where they can change: a cell's
  // activity depends on its 8 corners (cells vbox.lo - 1 .. vbox.hi - 1 can change), its
  // distance (capped: only active cells within DIST_MAX - 1 count) on the activity within
  // DIST_MAX - 1 cells, so the cells within DIST_MAX of a changed one are recomputed from
  // the voxels within 2 DIST_MAX, the rest of the volume reading as it is. The margin's
  // scale is the whole volume's; if it changed, every cell is recomputed.
  std::size_t lo = f.cell_dist.size(), hi = 0;
  const std::size_t cx = std::size_t(n[0] + 2), cy = std::size_t(n[1] + 2);
  std::vector<float> quad_rows;            // binding 12: the quads of the changed voxels, row by row
  std::vector<VkBufferCopy> quad_regions;  // (srcOffset: into quad_rows, bytes)
  if (!ids.empty()) {
    std::array<int, 3> vlo{n[0], n[1], n[2]}, vhi{0, 0, 0};  // changed voxels [vlo, vhi)
    for (std::uint32_t id : ids) {
      const int b[3] = {int(id % nb[0]), int(id / nb[0] % nb[1]), int(id / (std::uint64_t(nb[0]) * nb[1]))};
      for (int a = 0; a < 3; ++a) {
        vlo[a] = std::min(vlo[a], 8 * b[a]);
        vhi[a] = std::max(vhi[a], std::min(n[a], 8 * b[a] + 8));
      }
    }
    if (m.use_quads) {  // a voxel (x, y, z) is in the quads of base corners (x - 1 .. x, y - 1 .. y, z)
      const int qx0 = vlo[0] - 1, qx1 = vhi[0];
      for (int z = vlo[2]; z < vhi[2]; ++z)
        for (int y = vlo[1] - 1; y < vhi[1]; ++y) {
          const std::size_t o = quad_rows.size();
          quad_rows.resize(o + 4 * std::size_t(qx1 - qx0));
          quad_row(f, qx0, qx1, y, z, quad_rows.data() + o);
          quad_regions.push_back({o * sizeof(float), quad_index(n, qx0, y, z) * 16, std::size_t(qx1 - qx0) * 16});
        }
    }
    const bool none = m.dirty_lo[0] >= m.dirty_hi[0];
    for (int a = 0; a < 3; ++a) {  // the next render() draws again where these voxels show
      m.dirty_lo[a] = none ? vlo[a] : std::min(m.dirty_lo[a], vlo[a]);
      m.dirty_hi[a] = none ? vhi[a] : std::max(m.dirty_hi[a], vhi[a]);
    }
    // The margin's scale (value_magnitude): grown by a new value, else unchanged unless a
    // voxel that held it was overwritten (then scanned again).
    const double mag = new_max > m.mag ? new_max : max_changed ? value_magnitude(f.values, f.background) : m.mag;
    const int R = int(ISOTOUCH_RAYCAST_DIST_MAX);
    std::array<int, 3> olo{}, ohi{}, slo{}, shi{};  // cells [olo, ohi] recomputed; voxels [slo, shi) read
    for (int a = 0; a < 3; ++a) {
      olo[a] = std::max(-1, vlo[a] - 1 - R);
      ohi[a] = std::min(n[a], vhi[a] - 1 + R);
      slo[a] = std::max(0, vlo[a] - 1 - 2 * R - 1);
      shi[a] = std::min(n[a], vhi[a] + 2 * R + 1);
    }
    auto write = [&](std::size_t i, std::uint8_t v) {
      if (f.cell_dist[i] != v) {
        f.cell_dist[i] = v;
        lo = std::min(lo, i);
        hi = std::max(hi, i + 1);
      }
    };
    if (mag != m.mag) {
      const std::vector<std::uint8_t> cd = cell_distances_with(f.grid, f.values, f.iso, f.background, mag);
      for (std::size_t i = 0; i < cd.size(); ++i) write(i, cd[i]);
      m.mag = mag;
      st.cells_recomputed = cd.size();
      m.active = active_box(f);
    } else {
      core::Grid sub = f.grid;
      sub.dims = {shi[0] - slo[0], shi[1] - slo[1], shi[2] - slo[2]};
      std::vector<float> sv(sub.voxel_count());
      for (int z = slo[2]; z < shi[2]; ++z)
        for (int y = slo[1]; y < shi[1]; ++y) {
          const std::size_t from = (std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(slo[0]);
          const std::size_t to = (std::size_t(z - slo[2]) * std::size_t(sub.dims[1]) + std::size_t(y - slo[1])) * std::size_t(sub.dims[0]);
          std::copy(f.values.begin() + long(from), f.values.begin() + long(from) + sub.dims[0], sv.begin() + long(to));
        }
      const std::vector<std::uint8_t> cd = cell_distances_with(sub, sv, f.iso, f.background, mag);
      const std::size_t sx = std::size_t(sub.dims[0] + 2), sy = std::size_t(sub.dims[1] + 2);
      st.cells_recomputed = std::uint64_t(ohi[0] - olo[0] + 1) * std::uint64_t(ohi[1] - olo[1] + 1) * std::uint64_t(ohi[2] - olo[2] + 1);
      // The active box grows by the cells that turned active (cells that turned inactive
      // leave it as it was: a larger box only starts the skipping march earlier).
      std::array<int, 3> alo{n[0] + 1, n[1] + 1, n[2] + 1}, ahi{-2, -2, -2};
      for (int z = olo[2]; z <= ohi[2]; ++z)
        for (int y = olo[1]; y <= ohi[1]; ++y)
          for (int x = olo[0]; x <= ohi[0]; ++x) {  // cell c stored at c + 1, in both
            const std::uint8_t d = cd[(std::size_t(z - slo[2] + 1) * sy + std::size_t(y - slo[1] + 1)) * sx + std::size_t(x - slo[0] + 1)];
            write((std::size_t(z + 1) * cy + std::size_t(y + 1)) * cx + std::size_t(x + 1), d);
            if (d == 0) {
              alo = {std::min(alo[0], x), std::min(alo[1], y), std::min(alo[2], z)};
              ahi = {std::max(ahi[0], x), std::max(ahi[1], y), std::max(ahi[2], z)};
            }
          }
      if (ahi[0] >= -1) {  // cell c spans [c, c + 1]
        std::array<double, 3> lo3{double(alo[0]), double(alo[1]), double(alo[2])};
        std::array<double, 3> hi3{ahi[0] + 1.0, ahi[1] + 1.0, ahi[2] + 1.0};
        if (m.active)
          for (int a = 0; a < 3; ++a) {
            lo3[a] = std::min(lo3[a], m.active->first[a]);
            hi3[a] = std::max(hi3[a], m.active->second[a]);
          }
        m.active = std::pair{lo3, hi3};
      }
    }
  }
  VkBufferCopy cell_region{};  // binding 2 holds 4 cells per float (pack_cells)
  if (hi > lo) {
    lo /= 4;  // now texels
    hi = (hi + 3) / 4;
    cell_region = {0, lo * sizeof(float), (hi - lo) * sizeof(float)};
  }
  std::size_t bytes = 0;
  for (const VkBufferCopy& r : regions) bytes += r.size;
  st.value_bytes = bytes;
  st.cell_bytes = cell_region.size;
  st.quad_bytes = quad_rows.size() * sizeof(float);
  if (bytes + cell_region.size + st.quad_bytes > 0) {
    GpuBuffer up = make_buffer_or_throw(m.ctx, bytes + cell_region.size + st.quad_bytes, MemoryIntent::Upload,
                                        "raycast update staging");
    auto* dst = static_cast<std::uint8_t*>(up.mapped());
    std::size_t o = 0;
    for (VkBufferCopy& r : regions) {  // pack the rows, then read them from the staging buffer
      std::memcpy(dst + o, reinterpret_cast<const std::uint8_t*>(f.values.data()) + r.srcOffset, r.size);
      r.srcOffset = o;
      o += r.size;
    }
    if (cell_region.size) {  // the texels [lo, hi)
      const std::vector<float> packed = pack_cells(f.cell_dist, lo, hi);
      std::memcpy(dst + o, packed.data(), packed.size() * sizeof(float));
      cell_region.srcOffset = o;
      o += cell_region.size;
    }
    if (!quad_rows.empty()) {
      std::memcpy(dst + o, quad_rows.data(), st.quad_bytes);
      for (VkBufferCopy& r : quad_regions) r.srcOffset += o;
    }
    VkCommandBuffer cmd = m.ctx.begin_commands();
    if (!regions.empty()) vkCmdCopyBuffer(cmd, up.handle(), m.values.handle(), std::uint32_t(regions.size()), regions.data());
    if (cell_region.size) vkCmdCopyBuffer(cmd, up.handle(), m.cells.handle(), 1, &cell_region);
    if (!quad_regions.empty())
      vkCmdCopyBuffer(cmd, up.handle(), m.quads.handle(), std::uint32_t(quad_regions.size()), quad_regions.data());
    barrier_transfer_to_compute(cmd);
    m.ctx.submit_and_wait(cmd);
  }
  st.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return st;
}

RaycastFloor raycast_floor(VulkanContext& vk, int width, int height, std::uint32_t fetches, bool vec4, int frames,
                           std::uint64_t bytes) {
  if (width < 1 || height < 1 || frames < 1)
    throw std::invalid_argument("raycast floor: " + std::to_string(width) + " x " + std::to_string(height) + ", " +
                                std::to_string(frames) + " frames");
  // A power of two of floats in [2^14, 2^26] (64 KiB .. 256 MiB), at most `bytes`.
  const std::uint32_t kVoxels = std::bit_floor(std::uint32_t(std::clamp<std::uint64_t>(bytes / 4, 1u << 14, 1u << 26)));
  std::vector<float> vals(kVoxels);
  for (std::uint32_t i = 0; i < kVoxels; ++i) vals[i] = float(i % 1000);
  GpuBuffer up = make_buffer_or_throw(vk, kVoxels * 4, MemoryIntent::Upload, "floor values staging");
  GpuBuffer v = make_buffer_or_throw(vk, kVoxels * 4, MemoryIntent::DeviceLocal, "floor values");
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  GpuBuffer out = make_buffer_or_throw(vk, pixels * 4, MemoryIntent::DeviceLocal, "floor image");
  std::memcpy(up.mapped(), vals.data(), kVoxels * 4);
  VkCommandBuffer cmd = vk.begin_commands();
  record_copy(cmd, up, v, kVoxels * 4);
  barrier_transfer_to_compute(cmd);
  vk.submit_and_wait(cmd);
  DescriptorArena arena(vk, 2, 4);
  GpuTimer timer(vk, 2);
  ComputePipeline<gpu::RaycastFloorPush> pipe(vk, raycast_floor_spv, 2, "raycast floor", 0u,
                                              {fetches, (vec4 ? kVoxels / 4 : kVoxels) - 1, vec4 ? 1u : 0u}, 1u);
  if (vec4) pipe.set_texel_vec4(1u);
  std::vector<double> gpu, wall;
  for (int k = 0; k <= frames; ++k) {
    arena.reset();
    VkCommandBuffer cb = vk.begin_commands();
    timer.record_reset(cb);
    pipe.bind(cb, arena, {{v.handle(), 0, v.size()}, {out.handle(), 0, pixels * 4}});
    pipe.push(cb, gpu::RaycastFloorPush{std::uint32_t(width), std::uint32_t(height), 0, 0});
    timer.mark(cb, 0);
    vkCmdDispatch(cb, (std::uint32_t(width) + ISOTOUCH_RAYCAST_WG_X - 1) / ISOTOUCH_RAYCAST_WG_X, std::uint32_t(height), 1);
    barrier_compute_to_compute(cb);  // the timestamp after the dispatch's end (lavapipe may run it asynchronously)
    timer.mark(cb, 1);
    const double w = vk.submit_and_wait(cb);
    const double t = timer.elapsed_ms(0, 1);
    if (k == 0) continue;  // warm-up
    gpu.push_back(t >= 0 ? t : w);
    wall.push_back(w);
  }
  std::sort(gpu.begin(), gpu.end());
  std::sort(wall.begin(), wall.end());
  return {gpu[gpu.size() / 2], wall[wall.size() / 2], std::uint64_t(kVoxels) * 4};
}

}  // namespace isotouch::engine
