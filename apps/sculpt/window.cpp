#include "isotouch/apps/sculpt/window.h"

#include <chrono>
#include <thread>

#define GLFW_INCLUDE_NONE
#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>
#define GLFW_EXPOSE_NATIVE_X11
#include <GLFW/glfw3native.h>

#include <sched.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "isotouch/engine/device_memory.h"
#include "isotouch/engine/raycast.h"

namespace isotouch::sculpt {

using engine::Result;

namespace {
/// vkQueuePresentKHR from the CPUs of `off` (nullptr: where the thread is), then back to `own`.
VkResult present_from(VkQueue queue, const VkPresentInfoKHR& pi, const cpu_set_t* off, const cpu_set_t& own) {
  if (!off) return vkQueuePresentKHR(queue, &pi);
  const bool moved = sched_setaffinity(0, sizeof(cpu_set_t), off) == 0;
  const VkResult r = vkQueuePresentKHR(queue, &pi);
  if (moved) sched_setaffinity(0, sizeof(cpu_set_t), &own);
  return r;
}
}  // namespace

int Window::display_fd() const {
  Display* d = glfwGetX11Display();  // null (and a GLFW error) on another platform
  return d ? ConnectionNumber(d) : -1;
}

std::string Window::keep_present_off_cpu(int cpu) {
  present_off_ = false;
  if (cpu < 0) return "";
  if (sched_getaffinity(0, sizeof(cpu_set_t), &own_cpus_) != 0)
    return std::string("present: this thread's CPUs unknown (") + std::strerror(errno) + "): presents on any CPU";
  present_cpus_ = own_cpus_;
  if (cpu < CPU_SETSIZE) CPU_CLR(cpu, &present_cpus_);
  if (CPU_COUNT(&present_cpus_) == 0)
    return "present: no CPU but " + std::to_string(cpu) + " in this thread's set: presents there";
  present_off_ = true;
  return "";
}

engine::Result<std::vector<std::string>> init_glfw() {
  using R = Result<std::vector<std::string>>;
  glfwSetErrorCallback(nullptr);
  // A session that follows another (a dropped file, a new isovalue) may find the X server
  // resetting after its last client left (Xvfb without -noreset): try again for up to 2 s.
  bool up = glfwInit();
  for (int i = 0; !up && i < 20; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    up = glfwInit();
  }
  if (!up) {
    const char* why = nullptr;
    glfwGetError(&why);
    return R::fail(std::string("cannot open a window: glfwInit failed: ") + (why ? why : "no reason given") +
                   " (is DISPLAY set? headless: run under xvfb-run -a)");
  }
  if (!glfwVulkanSupported()) {
    glfwTerminate();
    return R::fail("cannot open a window: GLFW finds no Vulkan loader (Debian: libvulkan1)");
  }
  std::uint32_t n = 0;
  const char** names = glfwGetRequiredInstanceExtensions(&n);
  if (!names) {
    glfwTerminate();
    return R::fail("cannot open a window: no Vulkan surface extension for this window system");
  }
  std::vector<std::string> out(names, names + n);
  return R::ok(out);
}

void shutdown_glfw() { glfwTerminate(); }

Result<std::unique_ptr<Window>> Window::create(engine::VulkanContext& ctx, int width, int height,
                                               const std::string& title, PresentPath path) {
  using R = Result<std::unique_ptr<Window>>;
  std::unique_ptr<Window> w(new Window(ctx));
  glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
  w->win_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (!w->win_) {
    const char* why = nullptr;
    glfwGetError(&why);
    return R::fail(std::string("cannot create the window: ") + (why ? why : "GLFW gave no reason"));
  }
  // The size and the minimised state as the window starts, then as GLFW's events change them.
  glfwGetFramebufferSize(w->win_, &w->fb_[0], &w->fb_[1]);
  glfwGetWindowSize(w->win_, &w->win_size_[0], &w->win_size_[1]);
  w->iconified_ = glfwGetWindowAttrib(w->win_, GLFW_ICONIFIED) != 0;
  glfwSetWindowUserPointer(w->win_, w.get());
  glfwSetFramebufferSizeCallback(w->win_, [](GLFWwindow* h, int fw, int fh) {
    static_cast<Window*>(glfwGetWindowUserPointer(h))->fb_ = {fw, fh};
  });
  glfwSetWindowSizeCallback(w->win_, [](GLFWwindow* h, int ww, int wh) {
    static_cast<Window*>(glfwGetWindowUserPointer(h))->win_size_ = {ww, wh};
  });
  glfwSetWindowIconifyCallback(w->win_, [](GLFWwindow* h, int iconified) {
    static_cast<Window*>(glfwGetWindowUserPointer(h))->iconified_ = iconified != 0;
  });
  if (path == PresentPath::kShm || (path == PresentPath::kAuto && ctx.info().type == "cpu")) {
    w->shm_ = true;
    if (std::string e = w->make_offscreen(); !e.empty()) {
      w->destroy_offscreen();
      w->shm_ = false;
      if (path == PresentPath::kShm) return R::fail("cannot present through X shared memory: " + e);
      w->present_note_ = "X shared memory not used (" + e + "): the swapchain";
    }
  }
  if (!w->shm_) {
    if (const VkResult r = glfwCreateWindowSurface(ctx.instance(), w->win_, nullptr, &w->surface_); r != VK_SUCCESS)
      return R::fail(std::string("cannot create a Vulkan surface for the window: ") + engine::vk_result_name(r));
    VkBool32 ok = VK_FALSE;
    vkGetPhysicalDeviceSurfaceSupportKHR(ctx.physical_device(), ctx.queue_family(), w->surface_, &ok);
    if (!ok)
      return R::fail("Vulkan device '" + ctx.info().name + "' cannot present to this window from its compute queue");
  }
  VkDevice dev = ctx.device();
  VkSemaphoreCreateInfo si{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  VK_CHECK(vkCreateSemaphore(dev, &si, nullptr, &w->acquired_));
  VkFenceCreateInfo fi{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VK_CHECK(vkCreateFence(dev, &fi, nullptr, &w->fence_));
  VkCommandPoolCreateInfo pi{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pi.queueFamilyIndex = ctx.queue_family();
  VK_CHECK(vkCreateCommandPool(dev, &pi, nullptr, &w->pool_));
  VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  ai.commandPool = w->pool_;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  VK_CHECK(vkAllocateCommandBuffers(dev, &ai, &w->cmd_));
  if (!w->shm_)
    if (std::string e = w->make_swapchain(); !e.empty()) return R::fail(e);
  return R::ok(std::move(w));
}

Window::~Window() {
  VkDevice dev = ctx_.device();
  vkDeviceWaitIdle(dev);
  destroy_swapchain();
  destroy_offscreen();
  staging_.reset();
  if (pool_) vkDestroyCommandPool(dev, pool_, nullptr);
  if (fence_) vkDestroyFence(dev, fence_, nullptr);
  if (acquired_) vkDestroySemaphore(dev, acquired_, nullptr);
  if (surface_) vkDestroySurfaceKHR(ctx_.instance(), surface_, nullptr);
  if (win_) glfwDestroyWindow(win_);
}

const Window& Window::of(GLFWwindow* w) { return *static_cast<const Window*>(glfwGetWindowUserPointer(w)); }

bool Window::should_close() const { return glfwWindowShouldClose(win_); }

std::array<int, 2> Window::framebuffer_size() const {
  if (iconified_) return {0, 0};
  return fb_;
}

void Window::destroy_swapchain() {
  VkDevice dev = ctx_.device();
  if (hook_ && !images_.empty()) hook_->swapchain_gone();
  for (VkSemaphore s : done_) vkDestroySemaphore(dev, s, nullptr);
  done_.clear();
  images_.clear();
  if (swapchain_) vkDestroySwapchainKHR(dev, swapchain_, nullptr);
  swapchain_ = VK_NULL_HANDLE;
}

std::string Window::make_swapchain() {
  VkPhysicalDevice pd = ctx_.physical_device();
  VkDevice dev = ctx_.device();
  VkSurfaceCapabilitiesKHR caps{};
  VK_CHECK(vkGetPhysicalDeviceSurfaceCapabilitiesKHR(pd, surface_, &caps));
  if (!(caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT))
    return "the window's swapchain images cannot be copied into (no TRANSFER_DST usage)";
  if (hook_ && !(caps.supportedUsageFlags & VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT))
    return "the window's swapchain images cannot be drawn into (no COLOR_ATTACHMENT usage)";
  std::uint32_t n = 0;
  vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface_, &n, nullptr);
  std::vector<VkSurfaceFormatKHR> formats(n);
  vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface_, &n, formats.data());
  // The picture is already display-encoded (the ray caster's gamma): a UNORM image shows it as is.
  format_ = VK_FORMAT_UNDEFINED;
  VkColorSpaceKHR space = VK_COLOR_SPACE_SRGB_NONLINEAR_KHR;
  for (VkFormat want : {VK_FORMAT_R8G8B8A8_UNORM, VK_FORMAT_B8G8R8A8_UNORM})
    for (const auto& f : formats)
      if (format_ == VK_FORMAT_UNDEFINED && f.format == want) {
        format_ = f.format;
        space = f.colorSpace;
      }
  if (format_ == VK_FORMAT_UNDEFINED) return "the window offers neither an RGBA8 nor a BGRA8 UNORM swapchain format";
  swizzle_ = format_ == VK_FORMAT_B8G8R8A8_UNORM;
  vkGetPhysicalDeviceSurfacePresentModesKHR(pd, surface_, &n, nullptr);
  std::vector<VkPresentModeKHR> modes(n);
  vkGetPhysicalDeviceSurfacePresentModesKHR(pd, surface_, &n, modes.data());
  // Never wait for a vertical blank: the frame loop's own pace is what we measure.
  VkPresentModeKHR mode = VK_PRESENT_MODE_FIFO_KHR;
  present_mode_name_ = "fifo";
  for (auto [m, name] : {std::pair{VK_PRESENT_MODE_MAILBOX_KHR, "mailbox"}, std::pair{VK_PRESENT_MODE_IMMEDIATE_KHR, "immediate"}})
    if (mode == VK_PRESENT_MODE_FIFO_KHR && std::find(modes.begin(), modes.end(), m) != modes.end()) {
      mode = m;
      present_mode_name_ = name;
    }
  VkExtent2D ext = caps.currentExtent;
  if (ext.width == 0xFFFFFFFFu) {
    const auto fb = framebuffer_size();
    ext = {std::uint32_t(fb[0]), std::uint32_t(fb[1])};
  }
  ext.width = std::clamp(ext.width, caps.minImageExtent.width, caps.maxImageExtent.width);
  ext.height = std::clamp(ext.height, caps.minImageExtent.height, caps.maxImageExtent.height);
  if (ext.width == 0 || ext.height == 0) {  // minimised: try again when restored
    extent_ = ext;
    stale_ = true;
    return "";
  }
  std::uint32_t count = std::max(caps.minImageCount + 1, 2u);
  if (caps.maxImageCount) count = std::min(count, caps.maxImageCount);
  VkSwapchainCreateInfoKHR ci{VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR};
  ci.surface = surface_;
  ci.minImageCount = count;
  ci.imageFormat = format_;
  ci.imageColorSpace = space;
  ci.imageExtent = ext;
  ci.imageArrayLayers = 1;
  ci.imageUsage = VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  if (hook_) ci.imageUsage |= VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT;  // the hook draws into it
  ci.imageSharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ci.preTransform = caps.currentTransform;
  ci.compositeAlpha = (caps.supportedCompositeAlpha & VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR)
                          ? VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR
                          : VkCompositeAlphaFlagBitsKHR(caps.supportedCompositeAlpha & -caps.supportedCompositeAlpha);
  ci.presentMode = mode;
  ci.clipped = VK_TRUE;
  ci.oldSwapchain = swapchain_;
  VkSwapchainKHR sc = VK_NULL_HANDLE;
  if (const VkResult r = vkCreateSwapchainKHR(dev, &ci, nullptr, &sc); r != VK_SUCCESS)
    return std::string("cannot create the window's swapchain: ") + engine::vk_result_name(r);
  destroy_swapchain();
  swapchain_ = sc;
  extent_ = ext;
  vkGetSwapchainImagesKHR(dev, swapchain_, &n, nullptr);
  images_.resize(n);
  vkGetSwapchainImagesKHR(dev, swapchain_, &n, images_.data());
  VkSemaphoreCreateInfo si{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  done_.resize(n);
  for (auto& s : done_) VK_CHECK(vkCreateSemaphore(dev, &si, nullptr, &s));
  stale_ = false;
  if (hook_) return hook_->swapchain_ready(format_, extent_, images_, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR);
  return "";
}

Result<bool> Window::attach(FrameHook* hook) {
  using R = Result<bool>;
  VK_CHECK(vkDeviceWaitIdle(ctx_.device()));
  if (in_flight_) {
    VK_CHECK(vkWaitForFences(ctx_.device(), 1, &fence_, VK_TRUE, UINT64_MAX));
    VK_CHECK(vkResetFences(ctx_.device(), 1, &fence_));
    in_flight_ = false;
  }
  if (hook_ && !images_.empty()) hook_->swapchain_gone();
  hook_ = hook;
  if (!hook_) return R::ok(true);  // the images keep their usage: nothing to remake
  if (std::string e = remake(); !e.empty()) {
    if (!images_.empty()) hook_->swapchain_gone();
    hook_ = nullptr;
    stale_ = true;  // the next frame remakes a swapchain without the hook
    return R::fail(e);
  }
  return R::ok(true);
}

bool Window::acquire(std::uint32_t& index) {
  VkDevice dev = ctx_.device();
  if (in_flight_) {  // the previous copy has finished: its staging buffer and semaphores are free
    VK_CHECK(vkWaitForFences(dev, 1, &fence_, VK_TRUE, UINT64_MAX));
    VK_CHECK(vkResetFences(dev, 1, &fence_));
    in_flight_ = false;
  }
  const auto fb = framebuffer_size();
  if (fb[0] == 0 || fb[1] == 0) return false;
  const bool made = shm_ ? off_image_ != VK_NULL_HANDLE : swapchain_ != VK_NULL_HANDLE;
  if (stale_ || !made || std::uint32_t(fb[0]) != extent_.width || std::uint32_t(fb[1]) != extent_.height) {
    vkQueueWaitIdle(ctx_.queue());
    if (std::string e = remake(); !e.empty())
      throw engine::VulkanError(shm_ ? "the window's X shared-memory present: " + e : e);
    ++recreations_;
    if ((shm_ ? !off_image_ : !swapchain_) || stale_) return false;
  }
  if (shm_) {  // one image, free again once the last frame's fence passed (put_offscreen)
    index = 0;
    return true;
  }
  VkResult r = vkAcquireNextImageKHR(dev, swapchain_, UINT64_MAX, acquired_, VK_NULL_HANDLE, &index);
  if (r == VK_ERROR_OUT_OF_DATE_KHR) {
    stale_ = true;
    return false;
  }
  if (r == VK_SUBOPTIMAL_KHR) stale_ = true;  // present this one, then recreate
  else if (r != VK_SUCCESS) engine::vk_check_failed("vkAcquireNextImageKHR", r, __FILE__, __LINE__);
  return true;
}

bool Window::present(const std::vector<std::uint32_t>& rgba, int w, int h) { return present(rgba.data(), w, h, false); }

bool Window::present(const std::uint32_t* px, int w, int h, bool bgra) {
  std::uint32_t index = 0;
  if (!acquire(index)) return false;
  if (shm_) {
    compose_and_put(px, w, h, bgra);
    return true;
  }
  const VkDeviceSize bytes = VkDeviceSize(w) * VkDeviceSize(h) * 4;
  if (!staging_ || staging_.size() < bytes)
    staging_ = engine::make_buffer_or_throw(ctx_, bytes, engine::MemoryIntent::Upload, "window picture staging");
  auto* dst = static_cast<std::uint32_t*>(staging_.mapped());
  if (bgra != swizzle_) {
    for (std::size_t i = 0, e = std::size_t(w) * std::size_t(h); i < e; ++i) {
      const std::uint32_t p = px[i];
      dst[i] = engine::swap_red_blue(p);
    }
  } else {
    std::memcpy(dst, px, bytes);
  }
  copy_and_present(staging_.handle(), w, h, index);
  return true;
}

bool Window::present(VkBuffer pixels, int w, int h) {
  std::uint32_t index = 0;
  if (!acquire(index)) return false;
  copy_and_present(pixels, w, h, index);
  return true;
}

void Window::set_inset(const std::vector<std::uint32_t>& rgba, int x, int y, int w, int h) {
  inset_ = rgba;
  inset_x_ = x;
  inset_y_ = y;
  inset_w_ = inset_.empty() ? 0 : w;
  inset_h_ = inset_.empty() ? 0 : h;
  inset_dirty_ = true;
}

/// The inset's pixels into its staging buffer, in the swapchain's byte order: after acquire()
/// (the last copy, which read the buffer, is done), only when they changed.
void Window::upload_inset() {
  if (!inset_dirty_ || inset_.empty()) return;
  const VkDeviceSize bytes = VkDeviceSize(inset_.size()) * 4;
  if (!inset_staging_ || inset_staging_.size() < bytes)
    inset_staging_ = engine::make_buffer_or_throw(ctx_, bytes, engine::MemoryIntent::Upload, "window inset staging");
  auto* dst = static_cast<std::uint32_t*>(inset_staging_.mapped());
  for (std::size_t i = 0; i < inset_.size(); ++i) {
    const std::uint32_t p = inset_[i];
    dst[i] = swizzle_ ? engine::swap_red_blue(p) : p;
  }
  inset_dirty_ = false;
}

/// The inset over the picture just copied into `image` (TRANSFER_DST_OPTIMAL), cut to the extent.
void Window::copy_inset_into(VkImage image) {
  upload_inset();
  if (inset_.empty() || inset_x_ < 0 || inset_y_ < 0 || std::uint32_t(inset_x_) >= extent_.width ||
      std::uint32_t(inset_y_) >= extent_.height)
    return;
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
  VkBufferImageCopy region{};
  region.bufferRowLength = std::uint32_t(inset_w_);
  region.bufferImageHeight = std::uint32_t(inset_h_);
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageOffset = {inset_x_, inset_y_, 0};
  region.imageExtent = {std::min(std::uint32_t(inset_w_), extent_.width - std::uint32_t(inset_x_)),
                        std::min(std::uint32_t(inset_h_), extent_.height - std::uint32_t(inset_y_)), 1};
  vkCmdCopyBufferToImage(cmd_, inset_staging_.handle(), image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
}

void Window::copy_and_present(VkBuffer src, int w, int h, std::uint32_t index) {
  VK_CHECK(vkResetCommandBuffer(cmd_, 0));
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vkBeginCommandBuffer(cmd_, &bi));
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = 0;
  b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = images_[index];
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0, nullptr,
                       1, &b);
  // Black where the picture does not reach (a picture smaller than the swapchain's extent);
  // one that covers it is copied over the whole image (a clear first would cost a pass over
  // its pixels on a CPU device).
  if (std::uint32_t(w) < extent_.width || std::uint32_t(h) < extent_.height) {
    VkClearColorValue black{};
    vkCmdClearColorImage(cmd_, images_[index], VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, &black, 1, &b.subresourceRange);
    VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &mb, 0, nullptr, 0,
                         nullptr);
  }
  VkBufferImageCopy region{};
  region.bufferRowLength = std::uint32_t(w);
  region.bufferImageHeight = std::uint32_t(h);
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {std::min(std::uint32_t(w), extent_.width), std::min(std::uint32_t(h), extent_.height), 1};
  vkCmdCopyBufferToImage(cmd_, src, images_[index], VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  copy_inset_into(images_[index]);
  if (hook_) {
    hook_->record(cmd_, index);
  } else if (!shm_) {
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = 0;
    b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_PRESENT_SRC_KHR;
    vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, 0, 0, nullptr, 0,
                         nullptr, 1, &b);
  }
  if (shm_) {  // the host reads the rows next (the hook left the image GENERAL: swapchain_ready)
    b.srcAccessMask = hook_ ? VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT : VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    b.oldLayout = hook_ ? VK_IMAGE_LAYOUT_GENERAL : VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_GENERAL;
    vkCmdPipelineBarrier(cmd_, hook_ ? VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT : VK_PIPELINE_STAGE_TRANSFER_BIT,
                         VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 0, nullptr, 1, &b);
  }
  VK_CHECK(vkEndCommandBuffer(cmd_));
  const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_TRANSFER_BIT;
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd_;
  if (shm_) {
    put_offscreen(si);
    return;
  }
  si.waitSemaphoreCount = 1;
  si.pWaitSemaphores = &acquired_;
  si.pWaitDstStageMask = &wait_stage;
  si.signalSemaphoreCount = 1;
  si.pSignalSemaphores = &done_[index];
  VK_CHECK(vkQueueSubmit(ctx_.queue(), 1, &si, fence_));
  in_flight_ = true;
  VkPresentInfoKHR pi{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
  pi.waitSemaphoreCount = 1;
  pi.pWaitSemaphores = &done_[index];
  pi.swapchainCount = 1;
  pi.pSwapchains = &swapchain_;
  pi.pImageIndices = &index;
  const VkResult r = present_from(ctx_.queue(), pi, present_off_ ? &present_cpus_ : nullptr, own_cpus_);
  if (r == VK_ERROR_OUT_OF_DATE_KHR || r == VK_SUBOPTIMAL_KHR) stale_ = true;
  else if (r != VK_SUCCESS) engine::vk_check_failed("vkQueuePresentKHR", r, __FILE__, __LINE__);
}

// --- the shared-memory path ----------------------------------------------------------------

_XDisplay* Window::x_display() const { return glfwGetX11Display(); }
unsigned long Window::x_window() const { return glfwGetX11Window(win_); }

std::vector<std::uint32_t> Window::read_window() const {
  const auto fb = framebuffer_size();
  return ShmPicture::read_window(x_display(), x_window(), fb[0], fb[1]);
}

void Window::destroy_offscreen() {
  VkDevice dev = ctx_.device();
  if (hook_ && !images_.empty()) hook_->swapchain_gone();
  images_.clear();
  shm_picture_.reset();
  if (off_image_) vkDestroyImage(dev, off_image_, nullptr);
  if (off_memory_) {
    if (off_mapped_) vkUnmapMemory(dev, off_memory_);
    engine::count_free(off_memory_);
    vkFreeMemory(dev, off_memory_, nullptr);
  }
  off_image_ = VK_NULL_HANDLE;
  off_memory_ = VK_NULL_HANDLE;
  off_mapped_ = nullptr;
}

std::string Window::make_offscreen() {
  destroy_offscreen();
  const auto fb = framebuffer_size();
  if (fb[0] <= 0 || fb[1] <= 0) {  // minimised: try again when restored
    extent_ = {0, 0};
    stale_ = true;
    return "";
  }
  VkDevice dev = ctx_.device();
  const VkFormat format = VK_FORMAT_B8G8R8A8_UNORM;  // X's B, G, R, X bytes
  VkFormatProperties fp{};
  vkGetPhysicalDeviceFormatProperties(ctx_.physical_device(), format, &fp);
  VkFormatFeatureFlags need = VK_FORMAT_FEATURE_TRANSFER_DST_BIT;
  if (hook_) need |= VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BLEND_BIT;
  if ((fp.linearTilingFeatures & need) != need) return "the device cannot draw into a linear B8G8R8A8 image";
  auto picture = ShmPicture::create(x_display(), x_window(), fb[0], fb[1]);
  if (!picture) return picture.error;
  VkImageCreateInfo ci{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  ci.imageType = VK_IMAGE_TYPE_2D;
  ci.format = format;
  ci.extent = {std::uint32_t(fb[0]), std::uint32_t(fb[1]), 1};
  ci.mipLevels = 1;
  ci.arrayLayers = 1;
  ci.samples = VK_SAMPLE_COUNT_1_BIT;
  ci.tiling = VK_IMAGE_TILING_LINEAR;
  ci.usage = VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  if (hook_) ci.usage |= VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT;  // the hook draws into it
  ci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ci.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImageFormatProperties ip{};  // a linear image's limits can be tighter than the window
  if (vkGetPhysicalDeviceImageFormatProperties(ctx_.physical_device(), format, ci.imageType, ci.tiling, ci.usage, 0,
                                               &ip) != VK_SUCCESS ||
      ip.maxExtent.width < ci.extent.width || ip.maxExtent.height < ci.extent.height)
    return "the device's linear images are at most " + std::to_string(ip.maxExtent.width) + "x" +
           std::to_string(ip.maxExtent.height) + ", the window is " + std::to_string(fb[0]) + "x" + std::to_string(fb[1]);
  if (const VkResult r = vkCreateImage(dev, &ci, nullptr, &off_image_); r != VK_SUCCESS) {
    off_image_ = VK_NULL_HANDLE;
    return std::string("cannot create the window's image: ") + engine::vk_result_name(r);
  }
  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements(dev, off_image_, &req);
  const auto type = engine::find_memory(ctx_.memory_properties(), req.memoryTypeBits,
                                        VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, 0,
                                        req.size);
  if (!type) return "no host-visible memory for the window's image";
  VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  ai.allocationSize = req.size;
  ai.memoryTypeIndex = *type;
  if (const VkResult r = vkAllocateMemory(dev, &ai, nullptr, &off_memory_); r != VK_SUCCESS) {
    off_memory_ = VK_NULL_HANDLE;
    return std::string("cannot allocate the window's image: ") + engine::vk_result_name(r);
  }
  engine::count_allocation(off_memory_, req.size);
  if (const VkResult r = vkBindImageMemory(dev, off_image_, off_memory_, 0); r != VK_SUCCESS)
    return std::string("cannot bind the window's image memory: ") + engine::vk_result_name(r);
  void* mapped = nullptr;
  if (const VkResult r = vkMapMemory(dev, off_memory_, 0, VK_WHOLE_SIZE, 0, &mapped); r != VK_SUCCESS)
    return std::string("cannot map the window's image: ") + engine::vk_result_name(r);
  VkImageSubresource sub{VK_IMAGE_ASPECT_COLOR_BIT, 0, 0};
  VkSubresourceLayout layout{};
  vkGetImageSubresourceLayout(dev, off_image_, &sub, &layout);
  off_mapped_ = static_cast<const std::uint8_t*>(mapped) + layout.offset;
  off_row_pitch_ = layout.rowPitch;
  shm_picture_ = std::move(*picture.value);
  format_ = format;
  swizzle_ = true;
  extent_ = {std::uint32_t(fb[0]), std::uint32_t(fb[1])};
  images_ = {off_image_};
  stale_ = false;
  present_mode_name_ = "X11 shared memory";
  if (hook_) return hook_->swapchain_ready(format_, extent_, images_, VK_IMAGE_LAYOUT_GENERAL);
  return "";
}

void Window::compose_and_put(const std::uint32_t* px, int w, int h, bool bgra) {
  if (hook_) {
    VK_CHECK(vkResetCommandBuffer(cmd_, 0));
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    VK_CHECK(vkBeginCommandBuffer(cmd_, &bi));
    const bool recorded = hook_->record_layer(cmd_);
    VK_CHECK(vkEndCommandBuffer(cmd_));
    if (recorded) {
      VkDevice dev = ctx_.device();
      VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
      si.commandBufferCount = 1;
      si.pCommandBuffers = &cmd_;
      VK_CHECK(vkQueueSubmit(ctx_.queue(), 1, &si, fence_));
      VK_CHECK(vkWaitForFences(dev, 1, &fence_, VK_TRUE, UINT64_MAX));
      VK_CHECK(vkResetFences(dev, 1, &fence_));
    }
  }
  std::uint8_t* dst = shm_picture_->rows();
  const std::size_t stride = shm_picture_->stride();
  const int W = int(extent_.width), H = int(extent_.height);
  const int cw = std::min(w, W);
  for (int y = 0; y < H; ++y) {
    auto* row = reinterpret_cast<std::uint32_t*>(dst + std::size_t(y) * stride);
    int x = 0;
    if (y < h) {
      const std::uint32_t* src = px + std::size_t(y) * std::size_t(w);
      if (bgra) {
        std::memcpy(row, src, std::size_t(cw) * 4);
      } else {
        for (; x < cw; ++x) row[x] = engine::swap_red_blue(src[x]);
      }
      x = cw;
    }
    std::fill(row + x, row + W, 0xFF000000u);  // black where the picture does not reach
  }
  compose_inset(dst, stride);
  if (hook_) hook_->compose(dst, stride, W, H);
  shm_picture_->put();
}

void Window::compose_inset(std::uint8_t* rows, std::size_t stride) const {
  if (inset_.empty() || inset_x_ < 0 || inset_y_ < 0) return;
  const int W = int(extent_.width), H = int(extent_.height);
  const int x1 = std::min(inset_x_ + inset_w_, W), y1 = std::min(inset_y_ + inset_h_, H);
  for (int y = inset_y_; y < y1; ++y) {
    auto* row = reinterpret_cast<std::uint32_t*>(rows + std::size_t(y) * stride);
    const std::uint32_t* src = inset_.data() + std::size_t(y - inset_y_) * std::size_t(inset_w_);
    for (int x = inset_x_; x < x1; ++x) row[x] = engine::swap_red_blue(src[x - inset_x_]);
  }
}

void Window::put_offscreen(VkSubmitInfo& si) {
  VkDevice dev = ctx_.device();
  VK_CHECK(vkQueueSubmit(ctx_.queue(), 1, &si, fence_));
  VK_CHECK(vkWaitForFences(dev, 1, &fence_, VK_TRUE, UINT64_MAX));
  VK_CHECK(vkResetFences(dev, 1, &fence_));
  std::uint8_t* dst = shm_picture_->rows();
  const std::size_t row = std::size_t(extent_.width) * 4;
  for (std::uint32_t y = 0; y < extent_.height; ++y)
    std::memcpy(dst + std::size_t(y) * shm_picture_->stride(), off_mapped_ + VkDeviceSize(y) * off_row_pitch_, row);
  shm_picture_->put();
}

}  // namespace isotouch::sculpt
