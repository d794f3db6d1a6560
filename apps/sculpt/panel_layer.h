// panel_layer.h - the overlay's panels drawn into a layer of their own, for the shared-memory
// present path (window.h), where the host composes each frame anyway.
//
// On a CPU device drawing the Dear ImGui panels over every frame cost about 2.5 ms of a
// 1024 x 768 frame (llvmpipe rasterising and blending their triangles), although the panels
// change only when their figures are refreshed. The layer is drawn only when they change,
// into a linear, host-visible image cleared to transparent black: with ImGui's blending
// (colour SRC_ALPHA / ONE_MINUS_SRC_ALPHA, alpha ONE / ONE_MINUS_SRC_ALPHA) that leaves the
// panels' colour premultiplied by their coverage and the coverage in alpha, so blending the
// layer over a picture (out = L + D (1 - La)) gives what drawing the panels over it gives
// (exact in real arithmetic; the 8-bit rounding differs by at most a unit or two).
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "isotouch/engine/vk_context.h"

namespace isotouch::sculpt {

/// [x0, x1) x [y0, y1) in framebuffer pixels.
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

/// Blends a premultiplied B, G, R, A `layer` over B, G, R, X `rows` (both `w` x `h`, rows
/// `stride` / `layer_stride` bytes apart) inside `rects` (cut to the picture; a pixel in
/// several rects is blended once): per colour channel out = L + round(D (255 - La) / 255),
/// at most 255. Pixels outside the rects are left as they are.
void compose_premultiplied(std::uint8_t* rows, std::size_t stride, const std::uint8_t* layer,
                           std::size_t layer_stride, int w, int h, const std::vector<PixelRect>& rects);

/// The render pass the panels are drawn in: one colour attachment of `format`, one subpass,
/// the same dependencies in every form, so that ImGui's pipeline, made for one form, draws in
/// all (render passes that differ only in load op and layouts are compatible). Over the
/// picture: LOAD, from COLOR_ATTACHMENT_OPTIMAL; into the layer: CLEAR, from UNDEFINED.
VkResult make_panels_pass(VkDevice device, VkFormat format, VkAttachmentLoadOp load, VkImageLayout initial_layout,
                          VkImageLayout final_layout, VkRenderPass* pass);

class PanelLayer {
 public:
  /// A layer of `extent` in `format` (the window's B8G8R8A8), with a render pass that clears
  /// it to transparent black and leaves it GENERAL for the host's read, compatible with the
  /// overlay's own pass (same format and samples). Fails naming the step.
  static engine::Result<std::unique_ptr<PanelLayer>> create(engine::VulkanContext& ctx, VkFormat format,
                                                            VkExtent2D extent);
  ~PanelLayer();
  PanelLayer(const PanelLayer&) = delete;
  PanelLayer& operator=(const PanelLayer&) = delete;

  /// Begins the layer's render pass in `cmd` over the box of `rects` (cut to the layer),
  /// cleared there; the caller draws within the rects, then end(). Outside them the layer
  /// is never read.
  void begin(VkCommandBuffer cmd, const std::vector<PixelRect>& rects);
  /// Ends it and makes the colour writes visible to the host. `rects`: where the drawing
  /// lies (compose() blends only there).
  void end(VkCommandBuffer cmd, std::vector<PixelRect> rects);
  /// Blends the layer over `rows` (B, G, R, X, `w` x `h`, `stride` bytes apart) after the
  /// submission of begin()..end() completed. False when nothing is drawn in it.
  bool compose(std::uint8_t* rows, std::size_t stride, int w, int h) const;
  /// Nothing drawn: compose() blends nothing until the next end().
  void clear() { rects_.clear(); }

 private:
  explicit PanelLayer(engine::VulkanContext& ctx) : ctx_(ctx) {}
  engine::VulkanContext& ctx_;
  VkExtent2D extent_{0, 0};
  VkImage image_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  VkImageView view_ = VK_NULL_HANDLE;
  VkRenderPass pass_ = VK_NULL_HANDLE;
  VkFramebuffer framebuffer_ = VK_NULL_HANDLE;
  const std::uint8_t* mapped_ = nullptr;  // the first row
  std::size_t row_pitch_ = 0;
  std::vector<PixelRect> rects_;
};

}  // namespace isotouch::sculpt
