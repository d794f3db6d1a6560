#include "isotouch/apps/sculpt/overlay.h"
#include "isotouch/apps/sculpt/iso_panel.h"

#define GLFW_INCLUDE_NONE
#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>

#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_vulkan.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <array>
#include <utility>

namespace isotouch::sculpt {

using engine::Result;

namespace {

// ImGui's Vulkan backend reports each VkResult here: a failure is a bug, as with VK_CHECK.
void check_imgui_vk(VkResult r) {
  if (r < 0) engine::vk_check_failed("Dear ImGui's Vulkan backend", r, __FILE__, __LINE__);
}

bool queue_has_graphics(const engine::VulkanContext& ctx) {
  std::uint32_t n = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(ctx.physical_device(), &n, nullptr);
  std::vector<VkQueueFamilyProperties> q(n);
  vkGetPhysicalDeviceQueueFamilyProperties(ctx.physical_device(), &n, q.data());
  return ctx.queue_family() < n && (q[ctx.queue_family()].queueFlags & VK_QUEUE_GRAPHICS_BIT);
}

/// A value with its own -/+ buttons: the buttons do what the keys do.
template <class Step>
void step_buttons(const char* id, ToolState& tool, Step step) {
  ImGui::PushID(id);
  if (ImGui::SmallButton("-")) step(tool, false);
  ImGui::SameLine();
  if (ImGui::SmallButton("+")) step(tool, true);
  ImGui::PopID();
}

void tool_panel(ToolState& tool, IsoControl& iso, SliceControl& slices, MaterialsControl& materials) {
  ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowBgAlpha(0.8f);
  ImGui::Begin("Tool", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  using K = session::BrushKind;
  constexpr std::array<std::pair<K, const char*>, 4> kinds{
      {{K::kAdd, "add (1)"}, {K::kCarve, "carve (2)"}, {K::kSmooth, "smooth (3)"}, {K::kDrill, "drill (4)"}}};
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    if (i % 2) ImGui::SameLine();
    if (ImGui::RadioButton(kinds[i].second, tool.kind == kinds[i].first)) tool.kind = kinds[i].first;
  }
  float radius_mm = float(tool.radius_m * 1e3);
  if (ImGui::SliderFloat("radius mm ([ ])", &radius_mm, float(kMinRadiusM * 1e3), float(kMaxRadiusM * 1e3), "%.1f",
                         ImGuiSliderFlags_Logarithmic))
    tool.radius_m = std::clamp(double(radius_mm) * 1e-3, kMinRadiusM, kMaxRadiusM);
  ImGui::SameLine();
  step_buttons("radius", tool, step_radius);
  float strength = float(tool.strength);
  if (ImGui::SliderFloat("strength (- =)", &strength, float(kMinStrength), float(kMaxStrength), "%.2f",
                         ImGuiSliderFlags_Logarithmic))
    tool.strength = std::clamp(double(strength), kMinStrength, kMaxStrength);
  ImGui::SameLine();
  step_buttons("strength", tool, step_strength);
  // The isovalue: dragging shows the value; letting go restarts the session at it.
  float v = float(iso.value);
  ImGui::SliderFloat("isovalue", &v, float(iso.lo), float(iso.hi), "%.1f");
  if (ImGui::IsItemActive() || ImGui::IsItemEdited()) iso.value = std::clamp(double(v), iso.lo, iso.hi);
  if (ImGui::IsItemDeactivatedAfterEdit()) {
    iso.committed = true;
    iso.how = "hand (the slider)";
  }
  iso_histogram_widgets(iso);
  slice_widgets(slices);
  material_widgets(materials);
  ImGui::End();
}

void stats_panel(const PanelStats& s) {
  // Bottom left, out of the way of the volume, which the camera centres.
  // Placed again whenever the display's height or the panel's changed in the last two builds:
  // an auto-resized panel with wrapped text is tall in its first frames, and placed once it
  // stayed at the top, over the Tool panel. A panel the user moved stays until then.
  static float display_h = -1, panel_h[2] = {-1, -2};  // the last two builds' panel heights
  const float h = ImGui::GetIO().DisplaySize.y;
  const bool again = h != display_h || panel_h[0] != panel_h[1];
  ImGui::SetNextWindowPos(ImVec2(8, h - 8), again ? ImGuiCond_Always : ImGuiCond_FirstUseEver, ImVec2(0, 1));
  ImGui::SetNextWindowBgAlpha(0.8f);
  ImGui::Begin("Stats", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  display_h = h;
  panel_h[1] = panel_h[0];
  panel_h[0] = ImGui::GetWindowSize().y;
  ImGui::Text("servo       %.0f Hz (target %.0f Hz)", s.servo_rate_hz, s.servo_target_hz);
  ImGui::Text("ticks       %ld, missed deadlines %ld, faults %ld", s.ticks, s.missed_deadlines, s.faults);
  if (s.tick_p99_us && s.tick_p99_beyond) ImGui::Text("tick p99    > %.1f ms (|period error|, past the histogram)", *s.tick_p99_us * 1e-3);
  else if (s.tick_p99_us) ImGui::Text("tick p99    %.0f us (|period error|)", *s.tick_p99_us);
  else ImGui::TextDisabled("tick p99    n/a (no ticks yet)");
  if (s.edit_to_haptics_last_ms)
    ImGui::Text("edit->feel  %.2f ms last, %.2f ms median of recent", *s.edit_to_haptics_last_ms,
                s.edit_to_haptics_median_ms.value_or(0.0));
  else ImGui::TextDisabled("edit->feel  no edit yet");
  ImGui::Text("frame       %.1f ms (%.0f fps)", s.frame_ms, s.frame_ms > 0 ? 1e3 / s.frame_ms : 0.0);
  ImGui::Text("|F|         %.2f N%s", s.force_n, s.contact ? ", contact" : "");
  if (!s.passivity.empty()) ImGui::TextWrapped("passivity   %s", s.passivity.c_str());
  ImGui::Separator();
  ImGui::TextUnformatted(("volume      " + s.volume).c_str());
  if (!s.isovalue.empty()) ImGui::TextWrapped("%s", s.isovalue.c_str());
  ImGui::TextUnformatted(("device      " + s.device).c_str());
  if (!s.status.empty()) ImGui::TextWrapped("%s", s.status.c_str());
  if (!s.loading.empty()) {
    // The readers report no fraction done: the bar sweeps once a second while the file loads,
    // with the time so far (the session keeps running meanwhile).
    ImGui::TextWrapped("loading %s", s.loading.c_str());
    const std::string label = std::to_string(int(s.loading_s * 10) / 10) + "." + std::to_string(int(s.loading_s * 10) % 10) + " s";
    ImGui::ProgressBar(float(s.loading_s - std::floor(s.loading_s)), ImVec2(-1, 0), label.c_str());
  }
  ImGui::End();
}

}  // namespace

std::string Overlay::version() { return std::string("Dear ImGui ") + IMGUI_VERSION; }

Result<std::unique_ptr<Overlay>> Overlay::create(engine::VulkanContext& ctx, Window& window) {
  using R = Result<std::unique_ptr<Overlay>>;
  if (!queue_has_graphics(ctx))
    return R::fail("the Vulkan device's compute queue family cannot draw (no GRAPHICS): no overlay");
  std::unique_ptr<Overlay> o(new Overlay(ctx, window));
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  o->imgui_context_ = true;
  ImGuiIO& io = ImGui::GetIO();
  io.IniFilename = nullptr;  // no imgui.ini in the working folder: panels start where the code puts them
  ImGui::StyleColorsDark();
  // The app's own callbacks forward GLFW's events (mouse_button() etc.).
  if (!ImGui_ImplGlfw_InitForVulkan(window.handle(), false)) return R::fail("Dear ImGui's GLFW backend did not start");
  o->glfw_backend_ = true;
  if (std::string e = o->make_descriptor_pool(); !e.empty()) return R::fail(e);
  // The swapchain is remade with COLOR_ATTACHMENT usage; swapchain_ready() sets up the rest.
  if (auto a = window.attach(o.get()); !a) return R::fail(a.error);
  return R::ok(std::move(o));
}

Overlay::~Overlay() {
  vkDeviceWaitIdle(ctx_.device());
  window_.attach(nullptr);  // calls swapchain_gone() if attached
  swapchain_gone();
  shutdown_vulkan_backend();
  if (pool_) vkDestroyDescriptorPool(ctx_.device(), pool_, nullptr);
  if (glfw_backend_) ImGui_ImplGlfw_Shutdown();
  if (imgui_context_) ImGui::DestroyContext();
}

std::string Overlay::make_descriptor_pool() {
  // ImGui 1.86 needs one combined image sampler (its font texture); a few spare for a re-init.
  VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 4};
  VkDescriptorPoolCreateInfo ci{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  ci.flags = VK_DESCRIPTOR_POOL_CREATE_FREE_DESCRIPTOR_SET_BIT;
  ci.maxSets = 4;
  ci.poolSizeCount = 1;
  ci.pPoolSizes = &size;
  if (const VkResult r = vkCreateDescriptorPool(ctx_.device(), &ci, nullptr, &pool_); r != VK_SUCCESS)
    return std::string("cannot create the overlay's descriptor pool: ") + engine::vk_result_name(r);
  return "";
}

std::string Overlay::make_render_pass(VkFormat format, VkImageLayout final_layout) {
  // Draws over the picture (LOAD); record() moves the image to COLOR_ATTACHMENT_OPTIMAL first.
  if (const VkResult r = make_panels_pass(ctx_.device(), format, VK_ATTACHMENT_LOAD_OP_LOAD,
                                          VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, final_layout, &pass_);
      r != VK_SUCCESS) {
    pass_ = VK_NULL_HANDLE;
    return std::string("cannot create the overlay's render pass: ") + engine::vk_result_name(r);
  }
  format_ = format;
  final_layout_ = final_layout;
  return "";
}

std::string Overlay::init_vulkan_backend(VkFormat format, VkImageLayout final_layout) {
  if (std::string e = make_render_pass(format, final_layout); !e.empty()) return e;
  ImGui_ImplVulkan_InitInfo info{};
  info.Instance = ctx_.instance();
  info.PhysicalDevice = ctx_.physical_device();
  info.Device = ctx_.device();
  info.QueueFamily = ctx_.queue_family();
  info.Queue = ctx_.queue();
  info.DescriptorPool = pool_;
  // The window keeps one frame in flight (it waits for the previous one before recording),
  // so two sets of ImGui's vertex buffers suffice whatever the swapchain's image count.
  info.MinImageCount = 2;
  info.ImageCount = 2;
  info.MSAASamples = VK_SAMPLE_COUNT_1_BIT;
  info.CheckVkResultFn = check_imgui_vk;
  if (!ImGui_ImplVulkan_Init(&info, pass_)) return "Dear ImGui's Vulkan backend did not start";
  vulkan_backend_ = true;
  // The font atlas, uploaded once per backend start.
  VkCommandBuffer cmd = ctx_.begin_commands();
  if (!ImGui_ImplVulkan_CreateFontsTexture(cmd)) return "Dear ImGui could not record its font upload";
  ctx_.submit_and_wait(cmd);
  ImGui_ImplVulkan_DestroyFontUploadObjects();
  return "";
}

void Overlay::shutdown_vulkan_backend() {
  if (vulkan_backend_) {
    ImGui_ImplVulkan_Shutdown();
    VK_CHECK(vkResetDescriptorPool(ctx_.device(), pool_, 0));  // the font's set
    vulkan_backend_ = false;
  }
  if (pass_) vkDestroyRenderPass(ctx_.device(), pass_, nullptr);
  pass_ = VK_NULL_HANDLE;
  format_ = VK_FORMAT_UNDEFINED;
  final_layout_ = VK_IMAGE_LAYOUT_UNDEFINED;
}

std::string Overlay::swapchain_ready(VkFormat format, VkExtent2D extent, const std::vector<VkImage>& images,
                                     VkImageLayout final_layout) {
  swapchain_gone();
  shown_.reset();  // a new size: ImGui's display size and its draw data's projection follow it
  // The first swapchain, or a new format or final layout: ImGui's pipeline follows the render pass.
  if (format != format_ || final_layout != final_layout_) {
    shutdown_vulkan_backend();
    if (std::string e = init_vulkan_backend(format, final_layout); !e.empty()) return e;
  }
  VkDevice dev = ctx_.device();
  extent_ = extent;
  images_ = images;
  if (final_layout == VK_IMAGE_LAYOUT_GENERAL) {  // the shared-memory path: the host composes
    auto layer = PanelLayer::create(ctx_, format, extent);
    if (!layer) return layer.error;
    layer_ = std::move(*layer.value);
    layer_build_ = -1;
    layer_hash_.reset();
  }
  for (VkImage image : images) {
    VkImageViewCreateInfo vi{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
    vi.image = image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_2D;
    vi.format = format;
    vi.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    VkImageView view = VK_NULL_HANDLE;
    if (const VkResult r = vkCreateImageView(dev, &vi, nullptr, &view); r != VK_SUCCESS)
      return std::string("cannot create a view of a swapchain image: ") + engine::vk_result_name(r);
    views_.push_back(view);
    VkFramebufferCreateInfo fi{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
    fi.renderPass = pass_;
    fi.attachmentCount = 1;
    fi.pAttachments = &view;
    fi.width = extent.width;
    fi.height = extent.height;
    fi.layers = 1;
    VkFramebuffer fb = VK_NULL_HANDLE;
    if (const VkResult r = vkCreateFramebuffer(dev, &fi, nullptr, &fb); r != VK_SUCCESS)
      return std::string("cannot create the overlay's framebuffer: ") + engine::vk_result_name(r);
    framebuffers_.push_back(fb);
  }
  return "";
}

void Overlay::swapchain_gone() {
  VkDevice dev = ctx_.device();
  for (VkFramebuffer fb : framebuffers_) vkDestroyFramebuffer(dev, fb, nullptr);
  for (VkImageView v : views_) vkDestroyImageView(dev, v, nullptr);
  framebuffers_.clear();
  views_.clear();
  images_.clear();
  layer_.reset();
}

void Overlay::record(VkCommandBuffer cmd, std::uint32_t index) {
  // After the picture's copy: transfer writes done, then the image becomes a colour attachment.
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  b.newLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = images_[index];
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, 0, 0,
                       nullptr, 0, nullptr, 1, &b);
  VkRenderPassBeginInfo rb{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  rb.renderPass = pass_;
  rb.framebuffer = framebuffers_[index];
  rb.renderArea = {{0, 0}, extent_};
  vkCmdBeginRenderPass(cmd, &rb, VK_SUBPASS_CONTENTS_INLINE);
  ImDrawData* dd = ImGui::GetDrawData();
  if (dd && dd->TotalVtxCount > 0) {
    ImGui_ImplVulkan_RenderDrawData(dd, cmd);
    ++frames_drawn_;
  }
  vkCmdEndRenderPass(cmd);
}

namespace {

/// What ImGui's draw data would draw (vertices, indices, commands, the display), hashed: an
/// unchanged drawing need not be drawn again (a change is built three times: ImGui lays a
/// window out from its previous frame, so the builds after the first often draw the same).
std::uint64_t drawing_hash(const ImDrawData& dd) {
  std::uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  const float display[6] = {dd.DisplayPos.x, dd.DisplayPos.y, dd.DisplaySize.x, dd.DisplaySize.y,
                            dd.FramebufferScale.x, dd.FramebufferScale.y};
  mix(display, sizeof display);
  for (int i = 0; i < dd.CmdListsCount; ++i) {
    const ImDrawList& l = *dd.CmdLists[i];
    mix(l.VtxBuffer.Data, std::size_t(l.VtxBuffer.Size) * sizeof(ImDrawVert));
    mix(l.IdxBuffer.Data, std::size_t(l.IdxBuffer.Size) * sizeof(ImDrawIdx));
    for (const ImDrawCmd& c : l.CmdBuffer) {
      const float clip[4] = {c.ClipRect.x, c.ClipRect.y, c.ClipRect.z, c.ClipRect.w};
      const std::uint64_t ids[4] = {std::uint64_t(reinterpret_cast<std::uintptr_t>(c.TextureId)), c.VtxOffset,
                                    c.IdxOffset, c.ElemCount};
      mix(clip, sizeof clip);
      mix(ids, sizeof ids);
    }
  }
  return h;
}

/// Per draw list (a panel), the box of its vertices in framebuffer pixels (its clip
/// rectangles can be the whole display), a pixel wider on each side.
std::vector<PixelRect> drawing_rects(const ImDrawData& dd) {
  std::vector<PixelRect> rects;
  const ImVec2 o = dd.DisplayPos, sc = dd.FramebufferScale;
  for (int i = 0; i < dd.CmdListsCount; ++i) {
    const ImVector<ImDrawVert>& v = dd.CmdLists[i]->VtxBuffer;
    if (v.Size == 0) continue;
    float x0 = v[0].pos.x, y0 = v[0].pos.y, x1 = x0, y1 = y0;
    for (const ImDrawVert& q : v) {
      x0 = std::min(x0, q.pos.x), y0 = std::min(y0, q.pos.y);
      x1 = std::max(x1, q.pos.x), y1 = std::max(y1, q.pos.y);
    }
    rects.push_back({int(std::floor((x0 - o.x) * sc.x)) - 1, int(std::floor((y0 - o.y) * sc.y)) - 1,
                     int(std::ceil((x1 - o.x) * sc.x)) + 1, int(std::ceil((y1 - o.y) * sc.y)) + 1});
  }
  return rects;
}

}  // namespace

bool Overlay::record_layer(VkCommandBuffer cmd) {
  if (!layer_ || layer_build_ == frames_built_) return false;
  layer_build_ = frames_built_;
  ImDrawData* dd = ImGui::GetDrawData();
  // A drawing laid out for another size (the window was remade since the last build, or
  // ImGui's backend read a size the window's events have not reached yet) waits for the
  // next build, asked for here: a remake forces one, a size that came and went does not.
  const bool fits = dd && dd->TotalVtxCount > 0 && std::lround(dd->DisplaySize.x * dd->FramebufferScale.x) == long(extent_.width) &&
                    std::lround(dd->DisplaySize.y * dd->FramebufferScale.y) == long(extent_.height);
  if (!fits) {
    layer_->clear();
    layer_hash_.reset();
    shown_.reset();
    return false;
  }
  const std::uint64_t hash = drawing_hash(*dd);
  if (layer_hash_ == hash) return false;  // the same drawing: the layer holds it
  layer_hash_ = hash;
  std::vector<PixelRect> rects = drawing_rects(*dd);
  layer_->begin(cmd, rects);
  ImGui_ImplVulkan_RenderDrawData(dd, cmd);
  layer_->end(cmd, std::move(rects));
  ++layers_drawn_;
  return true;
}

void Overlay::compose(std::uint8_t* rows, std::size_t stride, int w, int h) {
  if (layer_ && layer_->compose(rows, stride, w, h)) ++frames_drawn_;
}

bool Overlay::changed(const Shown& now) const {
  if (touched_ || !shown_ || !(*shown_ == now) || !now.stats.loading.empty()) return true;  // the bar sweeps
  const ImGuiIO& io = ImGui::GetIO();
  return ImGui::IsAnyItemActive() || io.WantCaptureMouse || io.WantTextInput;
}

void Overlay::build(ToolState& tool, IsoControl& iso, SliceControl& slices, MaterialsControl& materials,
                    const PanelStats& stats, bool visible) {
  if (!vulkan_backend_) return;  // no swapchain yet (a minimised window): no font atlas either
  const Shown now{tool.kind, tool.radius_m, tool.strength, iso.value, iso.lo, iso.hi, slices.wl, slices.shown,
                  materials, stats, visible};
  if (changed(now)) settling_ = 3;  // this build and the two after it
  if (settling_ == 0) return;
  --settling_;
  shown_ = now;
  touched_ = false;
  ++frames_built_;
  ImGui_ImplVulkan_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  if (visible) {
    tool_panel(tool, iso, slices, materials);
    stats_panel(stats);
  }
  ImGui::Render();
}

bool Overlay::wants_mouse() const { return ImGui::GetIO().WantCaptureMouse; }
bool Overlay::wants_keyboard() const { return ImGui::GetIO().WantTextInput; }

void Overlay::mouse_button(GLFWwindow* w, int button, int action, int mods) {
  touched_ = true;
  ImGui_ImplGlfw_MouseButtonCallback(w, button, action, mods);
}
void Overlay::scroll(GLFWwindow* w, double dx, double dy) {
  touched_ = true;
  ImGui_ImplGlfw_ScrollCallback(w, dx, dy);
}
void Overlay::key(GLFWwindow* w, int k, int scancode, int action, int mods) {
  touched_ = true;
  ImGui_ImplGlfw_KeyCallback(w, k, scancode, action, mods);
}
void Overlay::character(GLFWwindow* w, unsigned int c) {
  touched_ = true;
  ImGui_ImplGlfw_CharCallback(w, c);
}

}  // namespace isotouch::sculpt
