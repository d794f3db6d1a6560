// raycast.h - first-hit isosurface ray casting of a volume: the GPU ray caster
// (shaders/raycast_*.comp, shared code raycast_common.glsl) and its CPU reference (engine/raycast_cpu.cpp, the same math).
//
// What is drawn: the isosurface {tau, inside} of the trilinear interpolation of the voxel
// values, every voxel outside the grid reading `background` (core::FieldView's field, the
// one the servo feels), refined to under 0.01 voxel along the ray, shaded from the
// central-difference gradient of that field; an optional clipping plane (the cut face of
// the object is drawn flat in `cap` colour); overlay primitives (spheres, discs, capsules,
// cones) for the probe, in grid-world [m].
//
// Frames: the camera, clip plane and primitives are in grid-world [m] (core::Grid:
// world = origin + spacing * index). OrbitCamera is given in the volume's physical frame
// (LPS for medical images: azimuth about physical +z (superior), azimuth 0 = looking from
// anterior (-y) toward +y) and turned into grid-world with the direction matrix D, so a
// RAS NIfTI and an LPS MetaImage of the same head both show the face from the front.
//
// Shader input (bindings of RaycastParams in shaders/isotouch_shared.h): dense float
// values + the distance of each trilinear cell (chessboard distance to the nearest cell that can
// hold an inside value; cell_distances(), rebuilt from the values whenever they change; one
// byte per cell on the host, 4 cells per float texel on the device), both uniform texel
// buffers: a volume up to maxTexelBufferElements voxels (2^27 on lavapipe: 512^3) renders
// one voxel per texel, a larger one 4 per texel (up to 2^29 voxels on lavapipe: a 512 x 512
// x 600 CT; the same floats, the same picture).
// Swapping in a bricked snapshot (core/brick_field.h) changes only the shader's voxel()
// (one brick-table lookup, then the 9^3 pool brick: a trilinear cell never straddles two
// bricks) and its bindings; the march and the CPU reference's voxel() change the same way,
// and the cell bytes of a uniform brick follow from its tile value.
#pragma once
#include "isotouch/engine/core_names.h"
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/engine/cpu_filters.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

using core::Vec3;

/// The field a ray caster draws: dense values on a grid plus its empty-space structure.
struct RaycastField {
  core::Grid grid;
  std::vector<float> values;          ///< grid.voxel_count() values, x fastest
  std::array<int, 3> bricks{0, 0, 0}; ///< ceil(dims / 8)
  /// (min, max) per brick, bricks x fastest: the 8^3 brick widened by 1 voxel on each
  /// side (engine::brick_minmax_cpu, halo 1), and for bricks on the grid's faces also
  /// the background (the one-voxel band outside the grid blends with it). Not read by the
  /// caster (the cell distances are finer); kept for callers that have GPU ranges.
  std::vector<float> brick_minmax;
  /// Empty-space skipping (binding 2 of the shader): one byte per trilinear cell c in
  /// [-1, n] per axis (stored at c + 1, x fastest; n + 2 cells per axis): the chessboard
  /// distance [cells] to the nearest active cell, 0 for an active one (cell_distances()).
  std::vector<std::uint8_t> cell_dist;
  core::Isosurface iso;
  float background = 0;  ///< value outside the grid (NaN: outside every isosurface)
};

/// The empty-space skipping structure of a volume (RaycastField::cell_dist), from the
/// values the caller gives (rebuild it when the volume changes: a function of the values
/// only, host side, O(cells x distance) word operations on bit sets).
/// Cell c (lower corner c, corners c + {0,1}^3, voxels outside the grid reading
/// `background`) is active when a corner value v has inside_sign * (v - tau) >= -margin,
/// margin = 1e-5 (max |finite v or background| + |tau|): the float lerps of a trilinear
/// value stay within 15 ulps of that bound of the corners' range, so an inactive cell's
/// samples are outside (a NaN corner makes every sample NaN: outside; it counts as
/// inactive). Returns (nx + 2)(ny + 2)(nz + 2) bytes: min(chessboard distance [cells] to the
/// nearest active cell, ISOTOUCH_RAYCAST_DIST_MAX), 0 for active cells. Cells past the
/// range are pure background: active only if the background is inside, and then every cell
/// on the range's faces is active too, so distances within the range are exact.
/// @throws std::invalid_argument if values.size() != grid.voxel_count().
std::vector<std::uint8_t> cell_distances(const core::Grid& grid, const std::vector<float>& values,
                                         const core::Isosurface& iso, float background);

/// Builds a RaycastField: brick ranges by brick_minmax_cpu(halo 1), widened at the faces,
/// and the cell distances (cell_distances()).
/// `background`: e.g. core::outside_background of the samples (what `isotouch run` publishes).
RaycastField make_raycast_field(const core::Grid& grid, std::vector<float> values, core::Isosurface iso,
                                float background);
/// The same from brick ranges computed elsewhere (the GPU brick_minmax pass, halo 1).
/// @throws std::invalid_argument if the ranges do not match the grid or the halo is not 1.
RaycastField make_raycast_field(const core::Grid& grid, std::vector<float> values, core::Isosurface iso,
                                float background, const BrickRanges& ranges);

/// Camera for one frame, grid-world [m]: eye, unit forward/right/up, vertical field of view.
struct CameraView {
  Vec3 eye, forward{0, 1, 0}, right{1, 0, 0}, up{0, 0, 1};
  double fov_y_deg = 30;
};

/// Orbit camera around a target, angles in the physical frame (see file comment).
struct OrbitCamera {
  double azimuth_deg = 0;    ///< about up_phys; 0: eye on the front side, 90: eye toward cross(up, front) (LPS: left)
  double elevation_deg = 10; ///< above the horizontal plane [deg], in (-90, 90)
  double distance_m = 0;     ///< eye to target [m]; 0: fit the volume's bounding sphere
  double zoom = 1;           ///< distance divided by this (> 0)
  double fov_y_deg = 30;     ///< vertical field of view [deg], in (0, 170)
  std::optional<Vec3> target_m;  ///< grid-world [m]; default: the grid's centre
  /// Physical direction shown up in the picture and the side the eye is on at azimuth 0
  /// (orthogonal unit vectors). Defaults: LPS superior up, anterior front. A volume stored
  /// upside down without saying so in its header (VTK's headsq: slice 0 is the top of the
  /// head, identity direction) needs up = (0, 0, -1).
  Vec3 up_phys{0, 0, 1};
  Vec3 front_phys{0, -1, 0};
};

/// Grid-world camera of an orbit camera. `direction` is D (row-major, physical = origin +
/// D (world - origin)); identity keeps the physical axes as grid axes.
/// @throws std::invalid_argument on out-of-range angles, zoom, fov or distance.
CameraView orbit_view(const core::Grid& grid, const std::array<double, 9>& direction, const OrbitCamera& cam);

/// A camera at `eye` looking at `target` with `up` (grid-world); up is made orthogonal.
CameraView look_at(const Vec3& eye, const Vec3& target, const Vec3& up, double fov_y_deg);

struct ClipPlane {
  Vec3 point_m;   ///< a point on the plane, grid-world [m]
  Vec3 normal;    ///< the removed side: dot(normal, p - point) > 0 is cut away
};

/// Drawing options of one frame.
struct RaycastStyle {
  bool skip_empty = true;          ///< empty-space skipping over the cell distances
  /// With skipping: a pass per tile of 8 x 8 pixels finds where its rays can first meet an
  /// active cell (cone stepping), and each pixel's march starts there. GPU only; the
  /// picture is the same either way (off: to measure what it saves).
  bool tile_starts = true;
  std::optional<ClipPlane> clip;   ///< cut away one half-space
  float step_vox = 0.5f;           ///< march step along the ray [voxels of index space]
  std::array<float, 3> surface{0.89f, 0.85f, 0.76f};  ///< albedo (linear)
  std::array<float, 3> background{0.08f, 0.09f, 0.12f};
  std::array<float, 3> cap{0.85f, 0.45f, 0.35f};      ///< the cut face
};

/// Overlay primitives (grid-world [m], colour linear 0..1).
gpu::RaycastPrim prim_sphere(const Vec3& centre, double radius_m, std::array<float, 3> rgb, float alpha = 1,
                             bool xray = false);
gpu::RaycastPrim prim_disc(const Vec3& centre, const Vec3& normal, double radius_m, std::array<float, 3> rgb,
                           float alpha);
gpu::RaycastPrim prim_capsule(const Vec3& a, const Vec3& b, double radius_m, std::array<float, 3> rgb,
                              float alpha = 1, bool xray = false);
gpu::RaycastPrim prim_cone(const Vec3& base, const Vec3& apex, double radius_m, std::array<float, 3> rgb);
/// An arrow from `from` to `to`: a capsule shaft and a cone head (head 25 % of the length).
void add_arrow(std::vector<gpu::RaycastPrim>& prims, const Vec3& from, const Vec3& to, double shaft_radius_m,
               std::array<float, 3> rgb);

/// One rendered frame. image: RGBA8 per pixel (R in the low byte), rows top to bottom;
/// depth: ray parameter t [m] of the isosurface (or cut face) hit, -1 where none.
struct RaycastImage {
  int width = 0, height = 0;
  std::vector<std::uint32_t> rgba;
  std::vector<float> depth;
  double gpu_ms = -1;        ///< GPU timestamps around the passes (-1: none / CPU)
  /// GPU time of the passes (-1: none / CPU): march (with the background fills and the
  /// tile-start pass before it; the pixels the box projects to), shade (hit pixels, with the hit count pass), overlay
  /// (0 without primitives).
  double march_ms = -1, shade_ms = -1, overlay_ms = -1;
  double tiles_ms = -1;      ///< the background fills and the tile-start pass (part of march_ms)
  /// GPU: the overlay's dispatches (0: no primitive drawn; 1: one pass; more: its stages,
  /// set_overlay_stages).
  int overlay_dispatches = 0;
  double submit_wall_ms = 0; ///< submit to fence (GPU; to the end of render()'s host work if later), or the whole CPU render
  /// GPU: the camera, style and size were the last frame's, so only the pixels where the
  /// voxels update() changed can show, and the overlay's old and new rectangles, were drawn
  /// again (the rest of the picture is the last frame's, as a full frame would draw it).
  bool reused = false;
};

/// The per-frame parameter block shared by GPU and CPU (flags not included).
gpu::RaycastParams make_params(const RaycastField& field, const CameraView& view, const RaycastStyle& style,
                               int width, int height);
std::uint32_t style_flags(const RaycastStyle& style);

/// Index-space length of one metre along a ray of grid-world direction `dir` (unit):
/// |dir / spacing|; t [m] times this is the distance in voxels.
double voxels_per_metre(const core::Grid& grid, const Vec3& dir);
/// The unit grid-world direction of pixel (px, py) in `view`, as the shader computes it (double).
Vec3 pixel_direction(const CameraView& view, int width, int height, int px, int py);

/// The shader's pack_rgba: linear colour 0..1 -> RGBA8 (R in the low byte, alpha 255),
/// display gamma sqrt, rounded to nearest. The GPU fills every pixel with the background's
/// packing before the march (engine/raycast.cpp), so host and shader must agree: this is
/// the CPU reference's own function.
std::uint32_t pack_rgba8(float r, float g, float b);

/// The floor of a ray-caster frame on this device (shaders/raycast_floor.comp): medians over
/// `frames` (after one warm-up frame) of a pass in which each of the width x height pixels'
/// invocations does `fetches` texel fetches of voxel values (4 floats each with `vec4`, else
/// 1) and one store, nothing else of a ray: device time [ms] (GPU timestamps) and submit to
/// fence [ms] (host clock). The values: `bytes` (a power of two of floats in 64 KiB .. 256 MiB,
/// at most `bytes`; pixel p's fetch i reads texel p + 67 i, wrapped).
struct RaycastFloor {
  double gpu_ms = 0, wall_ms = 0;
  std::uint64_t bytes = 0;  ///< the values fetched from
};
/// @throws std::invalid_argument on a size or frame count below 1.
RaycastFloor raycast_floor(VulkanContext& vk, int width, int height, std::uint32_t fetches, bool vec4, int frames,
                           std::uint64_t bytes = 1u << 20);

/// The CPU reference: the shader's math in float, one thread.
RaycastImage render_cpu(const RaycastField& field, const CameraView& view, const RaycastStyle& style, int width,
                        int height, const std::vector<gpu::RaycastPrim>& prims = {});

/// A packed pixel with its lowest and third bytes swapped (RGBA <-> BGRA, the order
/// RayCaster::set_bgra() selects).
inline std::uint32_t swap_red_blue(std::uint32_t p) { return (p & 0xFF00FF00u) | ((p & 0xFFu) << 16) | ((p >> 16) & 0xFFu); }

/// The GPU ray caster: created once per field (values and brick ranges uploaded and kept
/// resident), then render() any number of frames, from one thread at a time (a RayCaster
/// owns one descriptor arena and one timer).
class RayCaster {
 public:
  /// Fails (no throw), naming the volume's size and the device's limit, if a buffer
  /// exceeds maxMemoryAllocationSize or the voxels (4 per texel) or cells (4 per texel)
  /// exceed maxTexelBufferElements (one texel binding each).
  /// `quads`: also keep the voxels 4 per texel (binding 12), where they fit one texel
  /// binding, one allocation and 1 GiB: a trilinear sample then reads 2 texels instead of 8
  /// (the same floats in the same order: the same picture).
  /// `max_texels` (0: the device's maxTexelBufferElements; larger: the device's): the texels
  /// one binding may hold; voxels past it are read 4 per texel (four_voxels_per_texel()).
  /// A smaller one takes the large-volume path on a small volume (tests).
  /// The caster keeps `field` (pass a temporary or std::move it: no copy of the voxels).
  static Result<std::unique_ptr<RayCaster>> create(VulkanContext& ctx, RaycastField field, bool quads = true,
                                                   std::uint64_t max_texels = 0);
  /// Binding 12 holds the quads (create()).
  bool quads() const;
  /// Binding 1 holds the voxels 4 per texel: they exceed one binding of single floats (create()).
  bool four_voxels_per_texel() const;
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  /// Renders one frame: uploads parameters and primitives, the passes of
  /// shaders/raycast_common.glsl in one submission, reads back. With skipping, the march
  /// covers only the pixels the box of active cells projects to (rays elsewhere meet no
  /// active cell, so no inside sample), from each tile's start (RaycastStyle::tile_starts);
  /// without, the pixels the volume's box projects to.
  /// With the last frame's camera, style and size, only the pixels the voxels changed by
  /// update() since can reach (3 voxels wider), and the overlay's last and new rectangles,
  /// are drawn again (RaycastImage::reused); the picture is the one a full frame gives.
  /// `meanwhile` (if given) runs on this thread while the device draws (between the submit
  /// and the wait: host work that uses neither this caster nor its context's queue).
  /// @throws std::invalid_argument on a size outside [1, 8192] or too many primitives.
  RaycastImage render(const CameraView& view, const RaycastStyle& style, int width, int height,
                      const std::vector<gpu::RaycastPrim>& prims = {}, const std::function<void()>& meanwhile = {});
  /// Rows [y0, y1) of the picture render(view, style, width, height) draws without
  /// primitives (0 <= y0 < y1 <= height): the other rows keep what the buffers held. Drawn in
  /// order from row 0 to `height` with one camera, style and size (progressive refinement of
  /// a still view, a band per frame), the bands leave that picture, bit for bit, and the next
  /// render() with them reuses it (RaycastImage::reused: only what update() changed since the
  /// first band is drawn again). The image returned holds the band's rows only (height y1 -
  /// y0, its first row the picture's row y0); the buffers' other rows hold what the earlier
  /// bands drew, or another frame's (undefined after a size change).
  /// @throws std::invalid_argument on rows outside the picture or a size outside [1, 8192].
  RaycastImage render_rows(const CameraView& view, const RaycastStyle& style, int width, int height, int y0, int y1);
  const RaycastField& field() const;

  /// Where render() leaves its picture. Off (the default): RaycastImage::rgba and depth hold
  /// it. On: they stay empty and the picture stays in device memory until the next render()
  /// (image_buffer(), last_rgba(), last_depth()): a window copies it into its swapchain image
  /// without the host touching its pixels (on lavapipe a host copy of 4 bytes per pixel
  /// each, read back and into a staging buffer, is pure overhead).
  void set_in_place(bool on);
  /// Pixels packed B, G, R, A from the low byte in image_buffer() (a B8G8R8A8 swapchain's
  /// order) instead of R, G, B, A; RaycastImage::rgba and last_rgba() stay RGBA.
  void set_bgra(bool on);
  /// On: render() draws with march and shade pipelines that count their texel fetches
  /// (the same picture, slower: one atomic add per invocation); the next frame is drawn
  /// whole. For the floor of a frame (isotouch-sculpt --bench), not for drawing.
  void set_count_fetches(bool on);
  /// How the overlay pass draws the primitives. On (the default): in stages, each primitive
  /// over only its own pixels by a pipeline made for its kind (up to 32 list entries; more,
  /// or a frame whose stage buffer would not fit one binding, in one pass). Off: in one pass,
  /// every primitive at every pixel of their common rectangle. The same picture either way.
  void set_overlay_stages(bool on);
  /// The last render()'s counts (reads the device back): texel fetches (one voxel, quad or
  /// cell-distance texel each) of the marches and of the shading (refinement and normal, done
  /// by the march pass for its hits and by the shade pass for the rays it finishes), and the
  /// lanes of the fetches their subgroups made with at least one lane active (a vector's fetch
  /// costs all its lanes); hit pixels shaded (these 0 unless counting); the pixels the march
  /// handed to the shade pass (rays llvmpipe's loop budget stopped); the frame's pixels.
  struct FetchCount {
    std::uint64_t march = 0, shade = 0, march_lanes = 0, shade_lanes = 0, hits = 0, listed = 0, pixels = 0;
  };
  FetchCount last_fetches();
  /// The device buffer holding the last render()'s pixels (rows top to bottom, one 32-bit
  /// pixel each, set_bgra()'s order), written by compute shaders: a reader in a later
  /// submission needs a barrier from the compute stage's writes; the next render() waits
  /// for the transfers submitted before it (its first command is that barrier).
  VkBuffer image_buffer() const;
  /// The same pixels in host memory, where the device's memory is host-visible (a CPU
  /// device such as lavapipe: the picture is read in place, its writes made visible to the
  /// host when render() returns); nullptr elsewhere. Valid until the next render().
  const std::uint32_t* mapped_image() const;
  /// The last render()'s pixels, RGBA (reads the device buffer back).
  std::vector<std::uint32_t> last_rgba();
  /// The last render()'s depth at pixel (x, y): t [m] of the hit, -1 where none.
  /// @throws std::out_of_range outside the last frame.
  float last_depth(int x, int y);

  /// The last render()'s tile starts (tiles of ISOTOUCH_RAYCAST_TILE pixels, x fastest): the
  /// ray parameter t [m] before which no lattice sample of the tile's rays can be inside;
  /// +inf for a tile not marched (none can be, or outside the pixels that frame drew).
  /// Empty if that frame drew without tile starts. Reads the device buffer back (tests).
  std::vector<float> last_tile_starts();
  /// The last render()'s block starts (blocks of ISOTOUCH_RAYCAST_BLOCK pixels, x fastest):
  /// the same claim for the block's rays, from the block pass over the listed tiles; +inf
  /// for a block of a tile not listed. Empty without tile starts. Reads back (tests).
  std::vector<float> last_block_starts();

  /// What one update() did.
  struct UpdateStats {
    std::size_t bricks = 0;           ///< 8^3 bricks whose voxels were copied
    std::uint64_t value_bytes = 0;    ///< voxel bytes uploaded (the bricks' rows only)
    std::uint64_t cell_bytes = 0;     ///< cell-distance bytes uploaded (the span that changed, 4 cells per float)
    std::uint64_t quad_bytes = 0;     ///< quad bytes uploaded (the quads holding the bricks' voxels; 0 without quads)
    std::uint64_t cells_recomputed = 0;  ///< cells whose distance was recomputed on the host
    double ms = 0;                    ///< update(), everything included [ms]
  };
  /// The picture follows an edit: copies the voxels of bricks `bricks` (ids as in
  /// core/brick_field.h: 8^3 bricks, x fastest; duplicates allowed) from `values` (the whole
  /// edited volume, grid.voxel_count() values, x fastest) into the field and uploads only
  /// those bricks' rows to the device; the cell distances are recomputed on the host only
  /// within DIST_MAX cells of the changed voxels (from the voxels within 2 DIST_MAX; all of
  /// them if the margin's scale, the largest |value|, changed): the result equals a full
  /// rebuild's (cell_distances()), and only the span of bytes that changed is uploaded. The next render() then draws exactly what RayCaster::create
  /// on make_raycast_field(grid, values, ...) would draw (field().brick_minmax is not updated:
  /// the caster does not read it). Same thread as render().
  /// @throws std::invalid_argument on a size mismatch or an id out of range (names it).
  UpdateStats update(const std::vector<float>& values, const std::vector<std::uint32_t>& bricks);

 private:
  struct Impl;
  explicit RayCaster(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::engine
