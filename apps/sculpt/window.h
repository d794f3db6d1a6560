// window.h - a GLFW window that shows RGBA8 pictures through a Vulkan swapchain, or, on a
// CPU device and a local X server, through X shared memory.
//
// The compute ray caster draws into a buffer; present() copies that picture into the
// acquired swapchain image (vkCmdCopyBufferToImage, no graphics pipeline) and presents it.
// The swapchain is recreated when it is out of date or suboptimal or the framebuffer size
// changed; a minimised window (size 0) presents nothing until it is restored. A FrameHook
// (the Dear ImGui overlay) may draw over the picture before it is presented.
//
// The shared-memory path (PresentPath::kShm, the default on a CPU device where the X server
// offers MIT-SHM): the picture is copied into the window's own linear, host-visible image
// instead (the "swapchain" of one image the hook sees), and its rows go to the X server
// through a shared segment (shm_picture.h) instead of the X socket that a CPU device's
// swapchain writes them through.
#pragma once
#include <sched.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/apps/sculpt/shm_picture.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/vk_resources.h"

struct GLFWwindow;
struct _XDisplay;

namespace isotouch::sculpt {

/// GLFW's own set-up, once per process (glfwInit + the instance extensions a surface needs).
/// Fails with GLFW's message (no display, no Vulkan loader).
engine::Result<std::vector<std::string>> init_glfw();
void shutdown_glfw();

/// Drawing after the picture is in the swapchain image, recorded into the frame's command
/// buffer. Its resources that name swapchain images (views, framebuffers) follow the
/// swapchain: made in swapchain_ready(), released in swapchain_gone().
class FrameHook {
 public:
  virtual ~FrameHook() = default;
  /// The swapchain was (re)created with these images, which record() must leave in
  /// `final_layout` (PRESENT_SRC_KHR for a swapchain's; GENERAL for the shared-memory path's
  /// own image, which the host reads next), its colour writes made available to the
  /// COLOR_ATTACHMENT_OUTPUT stage's later barriers. Returns "" or why the hook cannot draw.
  virtual std::string swapchain_ready(VkFormat format, VkExtent2D extent, const std::vector<VkImage>& images,
                                      VkImageLayout final_layout) = 0;
  /// The swapchain's images are about to be destroyed (the device is idle).
  virtual void swapchain_gone() = 0;
  /// Records the drawing into image `index`, which the picture's copy left in
  /// TRANSFER_DST_OPTIMAL; the image must end in swapchain_ready()'s final layout.
  virtual void record(VkCommandBuffer cmd, std::uint32_t index) = 0;
  /// The shared-memory path, where the host composes each frame: records the hook's
  /// drawing into a layer of its own when it changed since the last call (true: recorded;
  /// the window submits it and waits before compose()); false: the last layer stands.
  virtual bool record_layer(VkCommandBuffer) { return false; }
  /// Blends that layer over the frame's rows (B, G, R, X bytes, `w` x `h`, `stride` bytes
  /// apart) on the host.
  virtual void compose(std::uint8_t* /*rows*/, std::size_t /*stride*/, int /*w*/, int /*h*/) {}
};

/// How frames reach the screen: kAuto = kShm on a CPU device (lavapipe) where it can be set
/// up (a local X server with MIT-SHM and a BGRX visual), else kSwapchain.
enum class PresentPath { kAuto, kShm, kSwapchain };

class Window {
 public:
  /// A window of `width` x `height` screen units on `ctx` (created with the extensions of
  /// init_glfw() and swapchain = true). Fails naming the step (surface, present support,
  /// surface format, transfer usage of swapchain images).
  /// `path` kShm where it cannot be set up fails naming why; kAuto falls back to the
  /// swapchain and says why in present_note().
  static engine::Result<std::unique_ptr<Window>> create(engine::VulkanContext& ctx, int width, int height,
                                                        const std::string& title,
                                                        PresentPath path = PresentPath::kAuto);
  ~Window();
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;

  GLFWwindow* handle() const { return win_; }
  bool should_close() const;
  /// Framebuffer size in pixels ({0, 0} while minimised), as GLFW's events last reported it
  /// (glfwPollEvents updates it): asking the X server costs two round trips per call, which
  /// wait for its CPU while the ray caster's threads hold both cores.
  std::array<int, 2> framebuffer_size() const;
  /// Framebuffer pixels per screen unit (the cursor's units), from the same events.
  double pixels_per_unit() const { return win_size_[0] > 0 ? double(fb_[0]) / win_size_[0] : 1.0; }
  /// The Window of a GLFW window this class created.
  static const Window& of(GLFWwindow* w);
  /// Shows `rgba` (R in the low byte, rows top to bottom, `w` x `h`) in the next swapchain
  /// image; the part outside the swapchain's extent is cut, the rest left as it was.
  /// Returns false when nothing was presented (minimised, swapchain recreated this frame).
  bool present(const std::vector<std::uint32_t>& rgba, int w, int h);
  /// The same from a device buffer holding the picture (4 bytes per pixel in the
  /// swapchain's byte order: bgra()), made available to transfer reads by the submission
  /// that wrote it (engine::RayCaster::image_buffer()): copied straight into the swapchain
  /// image, the host touches no pixel. The buffer must not change until the next present()
  /// (its copy is then done) or a later submission that waits for transfers.
  bool present(VkBuffer pixels, int w, int h);
  /// The same from host memory: `px` (`w` x `h`, rows top to bottom; B, G, R, A from the
  /// low byte where `bgra`, else R, G, B, A), e.g. a CPU device's mapped picture
  /// (engine::RayCaster::mapped_image()). On the shared-memory path the host composes the
  /// frame straight into the X segment (picture, inset, the hook's layer: no device copy, and
  /// the hook draws only when its drawing changed); elsewhere as present(rgba).
  bool present(const std::uint32_t* px, int w, int h, bool bgra);
  /// Frames go through X shared memory (present(px, ...) composes them on the host).
  bool host_composes() const { return shm_; }
  /// A picture (RGBA as present()'s, `w` x `h`) copied over every presented one at pixel
  /// (x, y) from the next present() on, until set again (the slice views); an empty one:
  /// none. The part outside the swapchain's extent is cut.
  void set_inset(const std::vector<std::uint32_t>& rgba, int x, int y, int w, int h);
  /// The swapchain's images are B8G8R8A8 (else R8G8B8A8).
  bool bgra() const { return swizzle_; }
  /// Draws `hook` into every presented frame from now on (nullptr: none), remaking the
  /// swapchain so that its images can be colour attachments. Fails naming why (no
  /// COLOR_ATTACHMENT usage, the hook's own set-up); the window then has no hook.
  engine::Result<bool> attach(FrameHook* hook);
  int recreations() const { return recreations_; }
  /// The socket of the window's X display connection, or -1 (not on X11).
  int display_fd() const;
  /// Presents from the other CPUs of this thread's set, never from `cpu` (-1: anywhere).
  /// On X11 a CPU device's present writes the whole image through the X socket in one
  /// system call, which a kernel without full preemption does not interrupt for a
  /// real-time thread woken on that CPU (the servo thread waited 2.4-7.5 ms behind it).
  /// Returns "" or why not (no other CPU in the set, the affinity refused): then anywhere.
  std::string keep_present_off_cpu(int cpu);
  /// "mailbox", "immediate" or "fifo" (the swapchain's), or "X11 shared memory".
  const std::string& present_mode() const { return present_mode_name_; }
  /// Why kAuto did not take the shared-memory path ("" if it did, or on a GPU).
  const std::string& present_note() const { return present_note_; }
  /// What the X server holds for the window now (framebuffer size, RGBA as present()'s,
  /// alpha 255): the pixels the user sees, after every request so far is done. Empty when
  /// they cannot be read (not on X11, a visual other than 8-bit TrueColor).
  std::vector<std::uint32_t> read_window() const;

 private:
  Window(engine::VulkanContext& ctx) : ctx_(ctx) {}
  std::string make_swapchain();  // "" or why not
  std::string remake() { return shm_ ? make_offscreen() : make_swapchain(); }
  /// The shared-memory path's image (framebuffer size, linear, host-visible, mapped) and
  /// its X picture: "" or why not.
  std::string make_offscreen();
  void destroy_offscreen();
  /// The shared-memory path: waits for the frame's copy and draws, then hands its rows to X.
  void put_offscreen(VkSubmitInfo& si);
  /// The shared-memory path composing on the host (present(px, ...)).
  void compose_and_put(const std::uint32_t* px, int w, int h, bool bgra);
  /// The inset's pixels over the host's rows (B, G, R, X).
  void compose_inset(std::uint8_t* rows, std::size_t stride) const;
  /// Waits for the last copy, remakes a stale swapchain, acquires an image: false if none.
  bool acquire(std::uint32_t& index);
  /// Copies `w` x `h` pixels of `src` into image `index` (the hook draws over it) and presents it.
  void copy_and_present(VkBuffer src, int w, int h, std::uint32_t index);
  void destroy_swapchain();
  /// The window's X display and window (null / 0 when not on X11).
  _XDisplay* x_display() const;
  unsigned long x_window() const;

  engine::VulkanContext& ctx_;
  GLFWwindow* win_ = nullptr;
  VkSurfaceKHR surface_ = VK_NULL_HANDLE;
  VkSwapchainKHR swapchain_ = VK_NULL_HANDLE;
  VkFormat format_ = VK_FORMAT_UNDEFINED;
  bool swizzle_ = false;  // BGRA swapchain: swap R and B
  VkExtent2D extent_{0, 0};
  std::vector<VkImage> images_;
  std::vector<VkSemaphore> done_;  // one per swapchain image: the copy finished, present may read
  VkSemaphore acquired_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  FrameHook* hook_ = nullptr;
  engine::GpuBuffer staging_;  // the picture, host-written, copied into the image
  // The inset: its pixels, where it goes, its staging copy (written after the last copy's fence).
  std::vector<std::uint32_t> inset_;
  int inset_x_ = 0, inset_y_ = 0, inset_w_ = 0, inset_h_ = 0;
  bool inset_dirty_ = false;
  engine::GpuBuffer inset_staging_;
  void upload_inset();
  void copy_inset_into(VkImage image);
  bool in_flight_ = false;
  bool stale_ = false;  // recreate before the next frame
  int recreations_ = 0;
  std::string present_mode_name_, present_note_;
  // The shared-memory path: its image and memory, where the rows lie, the X picture.
  bool shm_ = false;
  VkImage off_image_ = VK_NULL_HANDLE;
  VkDeviceMemory off_memory_ = VK_NULL_HANDLE;
  const std::uint8_t* off_mapped_ = nullptr;
  VkDeviceSize off_row_pitch_ = 0;
  std::unique_ptr<ShmPicture> shm_picture_;
  std::array<int, 2> fb_{0, 0};  // the framebuffer's size, from GLFW's size events
  std::array<int, 2> win_size_{0, 0};  // the window's, in screen units
  bool iconified_ = false;       // from GLFW's iconify events
  // The presenting thread's own CPUs, and the same without the CPU to keep off.
  cpu_set_t own_cpus_{}, present_cpus_{};
  bool present_off_ = false;  // present from present_cpus_
};

}  // namespace isotouch::sculpt
