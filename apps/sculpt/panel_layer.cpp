#include "isotouch/apps/sculpt/panel_layer.h"

#include <algorithm>
#include <string>
#include <utility>

#include "isotouch/engine/device_memory.h"
#include "isotouch/engine/vk_resources.h"

namespace isotouch::sculpt {

namespace {

/// round(c k / 255) for the two bytes of each 16-bit lane of x (c k <= 255 * 255: no carry
/// between lanes).
inline std::uint32_t scale_lanes(std::uint32_t x, std::uint32_t k) {
  x = x * k + 0x00800080u;
  return ((x + ((x >> 8) & 0x00FF00FFu)) >> 8) & 0x00FF00FFu;
}

/// A lane of 9 bits at most, saturated to 255.
inline std::uint32_t saturate_lanes(std::uint32_t x) {
  const std::uint32_t o = x & 0x01000100u;
  return (x | (o - (o >> 8))) & 0x00FF00FFu;
}

/// Premultiplied layer pixel l (B, G, R, A bytes) over picture pixel d (B, G, R, X): per
/// byte l + round(d (255 - A) / 255), at most 255 (an X byte of 255 stays 255). Two bytes
/// per operation (no branch: the compiler vectorises the loop over a span).
inline std::uint32_t over(std::uint32_t d, std::uint32_t l) {
  const std::uint32_t k = 255u - (l >> 24);
  const std::uint32_t rb = saturate_lanes(scale_lanes(d & 0x00FF00FFu, k) + (l & 0x00FF00FFu));
  const std::uint32_t ga = saturate_lanes(scale_lanes((d >> 8) & 0x00FF00FFu, k) + ((l >> 8) & 0x00FF00FFu));
  return rb | (ga << 8);
}

/// The x-intervals of `rects` on row y, merged (sorted, disjoint), cut to [0, w).
void row_spans(const std::vector<PixelRect>& rects, int y, int w, std::vector<std::pair<int, int>>& spans) {
  spans.clear();
  for (const PixelRect& r : rects)
    if (y >= r.y0 && y < r.y1) {
      const int a = std::max(r.x0, 0), b = std::min(r.x1, w);
      if (a < b) spans.emplace_back(a, b);
    }
  std::sort(spans.begin(), spans.end());
  std::size_t n = 0;
  for (const auto& s : spans) {
    if (n > 0 && s.first <= spans[n - 1].second) spans[n - 1].second = std::max(spans[n - 1].second, s.second);
    else spans[n++] = s;
  }
  spans.resize(n);
}

}  // namespace

void compose_premultiplied(std::uint8_t* rows, std::size_t stride, const std::uint8_t* layer,
                           std::size_t layer_stride, int w, int h, const std::vector<PixelRect>& rects) {
  std::vector<std::pair<int, int>> spans;
  for (int y = 0; y < h; ++y) {
    row_spans(rects, y, w, spans);
    std::uint8_t* d = rows + std::size_t(y) * stride;
    const std::uint8_t* l = layer + std::size_t(y) * layer_stride;
    for (const auto& [a, b] : spans) {
      auto* p = reinterpret_cast<std::uint32_t*>(d) + a;
      const auto* s = reinterpret_cast<const std::uint32_t*>(l) + a;
      for (int i = 0, n = b - a; i < n; ++i) p[i] = over(p[i], s[i]);
    }
  }
}

VkResult make_panels_pass(VkDevice device, VkFormat format, VkAttachmentLoadOp load, VkImageLayout initial_layout,
                          VkImageLayout final_layout, VkRenderPass* pass) {
  VkAttachmentDescription att{};
  att.format = format;
  att.samples = VK_SAMPLE_COUNT_1_BIT;
  att.loadOp = load;
  att.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  att.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  att.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  att.initialLayout = initial_layout;
  att.finalLayout = final_layout;
  VkAttachmentReference ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkSubpassDescription sub{};
  sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  sub.colorAttachmentCount = 1;
  sub.pColorAttachments = &ref;
  VkSubpassDependency deps[2]{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  // Out: the drawing and the final layout transition before the COLOR_ATTACHMENT_OUTPUT
  // stage of what follows (the window's barrier for the host's read, the present, or the
  // layer's own barrier).
  deps[1].srcSubpass = 0;
  deps[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].dstAccessMask = 0;
  VkRenderPassCreateInfo ci{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  ci.attachmentCount = 1;
  ci.pAttachments = &att;
  ci.subpassCount = 1;
  ci.pSubpasses = &sub;
  ci.dependencyCount = 2;
  ci.pDependencies = deps;
  return vkCreateRenderPass(device, &ci, nullptr, pass);
}

engine::Result<std::unique_ptr<PanelLayer>> PanelLayer::create(engine::VulkanContext& ctx, VkFormat format,
                                                               VkExtent2D extent) {
  using R = engine::Result<std::unique_ptr<PanelLayer>>;
  std::unique_ptr<PanelLayer> p(new PanelLayer(ctx));
  p->extent_ = extent;
  VkDevice dev = ctx.device();
  VkImageCreateInfo ci{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  ci.imageType = VK_IMAGE_TYPE_2D;
  ci.format = format;
  ci.extent = {extent.width, extent.height, 1};
  ci.mipLevels = 1;
  ci.arrayLayers = 1;
  ci.samples = VK_SAMPLE_COUNT_1_BIT;
  ci.tiling = VK_IMAGE_TILING_LINEAR;
  ci.usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT;
  ci.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  if (const VkResult r = vkCreateImage(dev, &ci, nullptr, &p->image_); r != VK_SUCCESS) {
    p->image_ = VK_NULL_HANDLE;
    return R::fail(std::string("cannot create the panels' layer: ") + engine::vk_result_name(r));
  }
  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements(dev, p->image_, &req);
  const auto type = engine::find_memory(ctx.memory_properties(), req.memoryTypeBits,
                                        VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, 0,
                                        req.size);
  if (!type) return R::fail("no host-visible memory for the panels' layer");
  VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  ai.allocationSize = req.size;
  ai.memoryTypeIndex = *type;
  if (const VkResult r = vkAllocateMemory(dev, &ai, nullptr, &p->memory_); r != VK_SUCCESS) {
    p->memory_ = VK_NULL_HANDLE;
    return R::fail(std::string("cannot allocate the panels' layer: ") + engine::vk_result_name(r));
  }
  engine::count_allocation(p->memory_, req.size);
  if (const VkResult r = vkBindImageMemory(dev, p->image_, p->memory_, 0); r != VK_SUCCESS)
    return R::fail(std::string("cannot bind the panels' layer memory: ") + engine::vk_result_name(r));
  void* mapped = nullptr;
  if (const VkResult r = vkMapMemory(dev, p->memory_, 0, VK_WHOLE_SIZE, 0, &mapped); r != VK_SUCCESS)
    return R::fail(std::string("cannot map the panels' layer: ") + engine::vk_result_name(r));
  VkImageSubresource sub{VK_IMAGE_ASPECT_COLOR_BIT, 0, 0};
  VkSubresourceLayout layout{};
  vkGetImageSubresourceLayout(dev, p->image_, &sub, &layout);
  p->mapped_ = static_cast<const std::uint8_t*>(mapped) + layout.offset;
  p->row_pitch_ = std::size_t(layout.rowPitch);

  VkImageViewCreateInfo vi{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  vi.image = p->image_;
  vi.viewType = VK_IMAGE_VIEW_TYPE_2D;
  vi.format = format;
  vi.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  if (const VkResult r = vkCreateImageView(dev, &vi, nullptr, &p->view_); r != VK_SUCCESS) {
    p->view_ = VK_NULL_HANDLE;
    return R::fail(std::string("cannot create a view of the panels' layer: ") + engine::vk_result_name(r));
  }

  // Cleared at the start; GENERAL at the end, for the host's read (end()'s barrier).
  if (const VkResult r = make_panels_pass(dev, format, VK_ATTACHMENT_LOAD_OP_CLEAR, VK_IMAGE_LAYOUT_UNDEFINED,
                                          VK_IMAGE_LAYOUT_GENERAL, &p->pass_);
      r != VK_SUCCESS) {
    p->pass_ = VK_NULL_HANDLE;
    return R::fail(std::string("cannot create the panels' layer pass: ") + engine::vk_result_name(r));
  }
  VkFramebufferCreateInfo fi{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
  fi.renderPass = p->pass_;
  fi.attachmentCount = 1;
  fi.pAttachments = &p->view_;
  fi.width = extent.width;
  fi.height = extent.height;
  fi.layers = 1;
  if (const VkResult r = vkCreateFramebuffer(dev, &fi, nullptr, &p->framebuffer_); r != VK_SUCCESS) {
    p->framebuffer_ = VK_NULL_HANDLE;
    return R::fail(std::string("cannot create the panels' layer framebuffer: ") + engine::vk_result_name(r));
  }
  return R::ok(std::move(p));
}

PanelLayer::~PanelLayer() {
  VkDevice dev = ctx_.device();
  if (framebuffer_) vkDestroyFramebuffer(dev, framebuffer_, nullptr);
  if (pass_) vkDestroyRenderPass(dev, pass_, nullptr);
  if (view_) vkDestroyImageView(dev, view_, nullptr);
  if (image_) vkDestroyImage(dev, image_, nullptr);
  if (memory_) {
    if (mapped_) vkUnmapMemory(dev, memory_);
    engine::count_free(memory_);
    vkFreeMemory(dev, memory_, nullptr);
  }
}

void PanelLayer::begin(VkCommandBuffer cmd, const std::vector<PixelRect>& rects) {
  int x0 = int(extent_.width), y0 = int(extent_.height), x1 = 0, y1 = 0;
  for (const PixelRect& r : rects) {
    x0 = std::min(x0, std::max(r.x0, 0)), y0 = std::min(y0, std::max(r.y0, 0));
    x1 = std::max(x1, std::min(r.x1, int(extent_.width))), y1 = std::max(y1, std::min(r.y1, int(extent_.height)));
  }
  if (x1 <= x0 || y1 <= y0) x0 = y0 = 0, x1 = y1 = 1;  // (an area of at least one pixel)
  VkClearValue clear{};  // transparent black: nothing drawn yet
  VkRenderPassBeginInfo rb{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  rb.renderPass = pass_;
  rb.framebuffer = framebuffer_;
  rb.renderArea = {{x0, y0}, {std::uint32_t(x1 - x0), std::uint32_t(y1 - y0)}};
  rb.clearValueCount = 1;
  rb.pClearValues = &clear;
  vkCmdBeginRenderPass(cmd, &rb, VK_SUBPASS_CONTENTS_INLINE);
}

void PanelLayer::end(VkCommandBuffer cmd, std::vector<PixelRect> rects) {
  vkCmdEndRenderPass(cmd);
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_GENERAL;
  b.newLayout = VK_IMAGE_LAYOUT_GENERAL;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image_;
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 0,
                       nullptr, 1, &b);
  rects_ = std::move(rects);
}

bool PanelLayer::compose(std::uint8_t* rows, std::size_t stride, int w, int h) const {
  if (rects_.empty()) return false;
  compose_premultiplied(rows, stride, mapped_, row_pitch_, std::min(w, int(extent_.width)),
                        std::min(h, int(extent_.height)), rects_);
  return true;
}

}  // namespace isotouch::sculpt
