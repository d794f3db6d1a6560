// overlay.h - the Dear ImGui panels over the sculpting window, and their GLFW and Vulkan glue.
//
// A tool panel (kind, radius, strength: the ToolState the keys change, within the same
// limits) and a stats panel (servo, latency, frame time, force, volume, device). ImGui draws
// into the swapchain image after the ray caster's picture was copied there (a FrameHook of
// the Window), so the picture itself, and the screenshots written from it, stay as they were.
// ImGui's GLFW backend installs no callbacks of its own: the app forwards its events here.
// Built only when CMake finds Dear ImGui (ISOTOUCH_WITH_IMGUI).
#pragma once
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tools.h"
#include "window.h"

namespace isotouch::sculpt {

/// The tool panel's isovalue slider: the session's isovalue, the volume's range; `committed`
/// is set (by build()) when the user lets go of a changed slider, with the new `value`.
struct IsoControl {
  double value = 0, lo = 0, hi = 1;  ///< value units (HU for CT)
  bool committed = false;
};

/// What the stats panel shows, filled by the frame loop.
struct PanelStats {
  double servo_target_hz = 0;
  double servo_rate_hz = 0;           ///< measured: ticks per second over the last refresh
  long ticks = 0, missed_deadlines = 0, faults = 0;
  std::optional<double> tick_p99_us;  ///< p99 |period error| [us] so far (session::LiveStats); none before two ticks
  bool tick_p99_beyond = false;       ///< past the histogram's range: the p99 is at least tick_p99_us
  std::optional<double> edit_to_haptics_last_ms, edit_to_haptics_median_ms;
  double frame_ms = 0;
  double force_n = 0;
  bool contact = false;
  std::string volume;                 ///< dims, spacing, orientation
  std::string device;                 ///< the haptic device and the status its last tick judged
  std::string status;                 ///< the last save, export or drop message
  std::string loading;                ///< a dropped file loading in the background ("" = none)
  double loading_s = 0;               ///< for this long [s]
};

class Overlay final : public FrameHook {
 public:
  /// ImGui on `window` (which gets this overlay as its FrameHook). Fails naming the step (no
  /// graphics on the window's queue, no COLOR_ATTACHMENT swapchain usage, a Vulkan object).
  static engine::Result<std::unique_ptr<Overlay>> create(engine::VulkanContext& ctx, Window& window);
  ~Overlay() override;
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;

  /// "Dear ImGui 1.86".
  static std::string version();
  /// This frame's panels (`visible` false: none); the tool widgets change `tool`, the isovalue
/// slider `iso` (the frame loop restarts the session at a committed value). Drawn by
  /// the window's next present().
  void build(ToolState& tool, IsoControl& iso, const PanelStats& stats, bool visible);
  /// The mouse is over a panel or dragging a widget: clicks and the wheel are ImGui's.
  bool wants_mouse() const;
  /// A text field (Ctrl+click on a slider) has the keyboard.
  bool wants_keyboard() const;
  /// Frames whose panels were drawn into the swapchain image.
  long frames_drawn() const { return frames_drawn_; }

  // GLFW events the app's callbacks forward.
  void mouse_button(GLFWwindow* w, int button, int action, int mods);
  void scroll(GLFWwindow* w, double dx, double dy);
  void key(GLFWwindow* w, int key, int scancode, int action, int mods);
  void character(GLFWwindow* w, unsigned int c);

  // FrameHook
  std::string swapchain_ready(VkFormat format, VkExtent2D extent, const std::vector<VkImage>& images) override;
  void swapchain_gone() override;
  void record(VkCommandBuffer cmd, std::uint32_t index) override;

 private:
  Overlay(engine::VulkanContext& ctx, Window& window) : ctx_(ctx), window_(window) {}
  std::string make_descriptor_pool();
  std::string make_render_pass(VkFormat format);
  std::string init_vulkan_backend(VkFormat format);
  void shutdown_vulkan_backend();

  engine::VulkanContext& ctx_;
  Window& window_;
  bool imgui_context_ = false, glfw_backend_ = false, vulkan_backend_ = false;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
  VkRenderPass pass_ = VK_NULL_HANDLE;
  VkFormat format_ = VK_FORMAT_UNDEFINED;  // the render pass's
  VkExtent2D extent_{0, 0};
  std::vector<VkImage> images_;  // the swapchain's, not owned
  std::vector<VkImageView> views_;
  std::vector<VkFramebuffer> framebuffers_;
  long frames_drawn_ = 0;
};

}  // namespace isotouch::sculpt
