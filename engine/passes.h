// passes.h - a chain of compute passes over one volume, GPU-resident between passes,
// and its one-thread CPU reference.
//
// A scene lists the passes it needs as PassDesc {kind, parameters}; PassChain creates
// only the pipelines and buffers that list needs, uploads the volume once, records every
// pass into ONE command buffer (ping-pong device-local buffers, a compute->compute barrier
// between dispatches that depend on each other) and reads back only the outputs.
//
// Passes (all with clamp-to-edge borders; grid spacing from the volume, sigma/radius in mm):
// - gaussian(sigma_mm): separable Gaussian, x then y then z; per-axis sigma in voxels =
//   sigma_mm / spacing_mm, radius ceil(3 sigma_vox), weights normalised in double and
//   rounded to float once (engine/cpu_filters.h gaussian_kernel), passed in a buffer.
// - closing(radius_mm): grayscale closing = dilation (max) then erosion (min) with a BOX
//   structuring element of half-widths floor(radius_mm / spacing_mm) per axis, done
//   separably (exact for a box: max over a box = max over x of max over y of max over z).
//   A box is a superset of the ellipsoidal ball of the same radius: it closes gaps up to
//   the box's width along every axis and up to sqrt(3) x that along diagonals.
// - gradient: shaders/gradient.comp on the current field (value + central differences).
// - brick_minmax(halo): (min, max) of every 8^3 brick widened by `halo` voxels (default 1:
//   the one-voxel stencil of the gradient, so the range covers every voxel a trilinear
//   sample or a gradient at a voxel in the brick reads).
// Filters replace the current field; gradient and brick_minmax read it. Each of gradient
// and brick_minmax may appear once. Where rows hold whole quads and the field is one binding
// and one texel view, each pass runs over the whole field in the forms lavapipe runs fastest
// (four voxels per invocation, texel fetches, vec4 stores; `bench engine` times them beside
// the same forms as standalone passes): a Gaussian with radii <= ISOTOUCH_FUSED_MAX_RADIUS as
// three passes (shaders/gauss_axis_x4.comp), the gradient as one (gradient_whole_x4.comp),
// brick_minmax(1) as each slice's brick row segments (minmax_segments.comp) reduced into the
// bricks (minmax_slices.comp). Otherwise by z-slabs (filter_x4, gradient_x4, minmax_rows +
// minmax_bricks).
//
// GPU and CPU do the same float operations in the same order (precise accumulation,
// -ffp-contract=off): on lavapipe every output agrees bit for bit (tests/test_passes.cpp).
#pragma once
#include "isotouch/engine/core_names.h"
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/vk_resources.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

/// The GPU chain. Create once per pass list, run on any number of volumes.
class PassChain {
 public:
  /// @param shaders Current (default) or the Legacy dense shaders (bench engine compares
  ///        them); same outputs bit for bit.
  /// @return error (no throw) if validate_passes() fails.
  static Result<std::unique_ptr<PassChain>> create(VulkanContext& ctx, std::vector<PassDesc> passes,
                                                   ShaderSet shaders = ShaderSet::Current);
  ~PassChain();
  PassChain(const PassChain&) = delete;
  PassChain& operator=(const PassChain&) = delete;

  /// Runs every pass in order in one command buffer.
  /// @param max_binding_bytes if non-zero, a smaller binding limit than the device's
  ///        (tests force many z-slabs with it).
  /// @throws VolumeError naming the volume if a buffer exceeds maxMemoryAllocationSize,
  ///         a slab does not fit a binding, or a parameter gives too wide a kernel.
  ChainOutput run(const Volume& volume, std::uint64_t max_binding_bytes = 0);

  /// The outputs where they lie, valid until the next run: the field after the last filter
  /// (null without a filter) and the gradient samples (null without a gradient). Where
  /// device-local memory is host-visible they point into the chain's own buffers (no copy);
  /// otherwise into `copies`, which run() filled as usual.
  struct InPlace {
    const float* field = nullptr;
    const core::Sample* samples = nullptr;
  };
  ChainOutput run_in_place(const Volume& volume, InPlace& where, std::uint64_t max_binding_bytes = 0);

  /// What this chain runs and what it left out: the passes in order, the pipelines and
  /// buffers created and those not created; after run(), per-pass kernel sizes in voxels
  /// and dispatch counts of the last run.
  std::string describe() const;
  const std::vector<PassDesc>& passes() const { return passes_; }

 private:
  ChainOutput run_impl(const Volume& volume, std::uint64_t max_binding_bytes, InPlace* in_place);
  struct Impl;
  explicit PassChain(std::unique_ptr<Impl> impl, std::vector<PassDesc> passes);
  std::unique_ptr<Impl> impl_;
  std::vector<PassDesc> passes_;
};

/// Specialization constants of shaders/gauss_fused_list.comp (the Gaussian's x, y and z
/// passes in one): the grid's size, the radii and the 2 r + 1 float weights of each axis,
/// bit for bit. Every radius <= ISOTOUCH_FUSED_MAX_RADIUS.
std::vector<std::uint32_t> fused_gaussian_spec(const std::array<int, 3>& dims,
                                               const std::array<std::vector<float>, 3>& kernels);

}  // namespace isotouch::engine
