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

#include "isotouch/apps/sculpt/panel_layer.h"
#include "isotouch/apps/sculpt/slice_views.h"
#include "isotouch/apps/sculpt/tools.h"
#include "isotouch/apps/sculpt/window.h"

namespace isotouch::sculpt {

/// The tool panel's isovalue slider: the session's isovalue, the volume's range; `committed`
/// is set (by build()) when the user lets go of a changed slider, with the new `value`.
struct IsoControl {
  double value = 0, lo = 0, hi = 1;  ///< value units (HU for CT)
  bool committed = false;
  /// How the committed value was set, for the stats panel's rule line after the restart:
  /// "hand (the slider)", "the preset bone", ...
  std::string how;
  /// The volume's histogram for the panel: log(1 + count) of equal bins over [lo, hi]; the
  /// isovalue is marked on it and dragging on it moves the isovalue (iso_panel.h).
  std::vector<float> histogram;
  std::vector<std::pair<std::string, double>> presets;  ///< name, isovalue (CT in HU: bone, soft tissue / skin, lung)
};

/// What the stats panel shows, filled by the frame loop.
struct PanelStats {
  double servo_target_hz = 0;
  double servo_rate_hz = 0;           ///< measured: ticks per second over the last refresh
  long ticks = 0, missed_deadlines = 0, faults = 0;
  std::optional<double> tick_p99_us;  ///< p99 |period error| [us] so far (session::LiveStats); none before two ticks
  bool tick_p99_beyond = false;       ///< past the histogram's range: the p99 is at least tick_p99_us
  std::optional<double> edit_to_haptics_last_ms, edit_to_haptics_median_ms;
  double frame_ms = 0;                ///< the mean over the frames since the last refresh (every 15 frames)
  double force_n = 0;                 ///< |F| and contact at the last refresh
  bool contact = false;
  std::string passivity;              ///< the servo's passivity stage (servo::describe; "" = no servo thread)
  std::string volume;                 ///< dims, spacing, orientation
  std::string isovalue;               ///< the chosen isovalue and its rule ("" = given by the user or scene)
  std::string device;                 ///< the haptic device and the status its last tick judged
  std::string status;                 ///< the last save, export or drop message
  std::string loading;                ///< a dropped file loading in the background ("" = none)
  double loading_s = 0;               ///< for this long [s]
  bool operator==(const PanelStats&) const = default;
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
  /// slider `iso` (the frame loop restarts the session at a committed value), the slice views'
  /// window/level `slices`. Drawn by
  /// the window's next present(). Built again only when something they show changed, the
  /// user touched them (an event forwarded since the last build, a widget active or hovered,
  /// a text field open) or the swapchain was remade, and in the two frames after that (ImGui
  /// lays a window out from its previous frame); otherwise the window draws the last
  /// build again (ImGui keeps its draw data until the next frame starts): a build costs the
  /// GLFW backend's X server round trips (focus, cursor, window and framebuffer size).
  /// `materials`: a labelled scene's materials section of the tool panel (slice_views.h;
  /// empty: none).
  void build(ToolState& tool, IsoControl& iso, SliceControl& slices, MaterialsControl& materials, const PanelStats& stats,
             bool visible);
  /// The frames whose panels were built anew (the rest drew the last build again).
  long frames_built() const { return frames_built_; }
  /// The mouse is over a panel or dragging a widget: clicks and the wheel are ImGui's.
  bool wants_mouse() const;
  /// A text field (Ctrl+click on a slider) has the keyboard.
  bool wants_keyboard() const;
  /// Frames that showed the panels: drawn into the swapchain image, or their layer blended
  /// over the frame (the shared-memory path).
  long frames_drawn() const { return frames_drawn_; }

  // GLFW events the app's callbacks forward.
  void cursor_moved() { touched_ = true; }  ///< ImGui's backend polls the cursor in the next build
  void mouse_button(GLFWwindow* w, int button, int action, int mods);
  void scroll(GLFWwindow* w, double dx, double dy);
  void key(GLFWwindow* w, int key, int scancode, int action, int mods);
  void character(GLFWwindow* w, unsigned int c);

  // FrameHook
  std::string swapchain_ready(VkFormat format, VkExtent2D extent, const std::vector<VkImage>& images,
                              VkImageLayout final_layout) override;
  void swapchain_gone() override;
  void record(VkCommandBuffer cmd, std::uint32_t index) override;
  /// The shared-memory path: the panels into their own layer (panel_layer.h) only when a
  /// build changed them, blended over each frame on the host.
  bool record_layer(VkCommandBuffer cmd) override;
  void compose(std::uint8_t* rows, std::size_t stride, int w, int h) override;
  /// Frames whose panels' layer was drawn anew (the shared-memory path).
  long layers_drawn() const { return layers_drawn_; }

 private:
  Overlay(engine::VulkanContext& ctx, Window& window) : ctx_(ctx), window_(window) {}
  std::string make_descriptor_pool();
  std::string make_render_pass(VkFormat format, VkImageLayout final_layout);
  std::string init_vulkan_backend(VkFormat format, VkImageLayout final_layout);
  void shutdown_vulkan_backend();

  engine::VulkanContext& ctx_;
  Window& window_;
  bool imgui_context_ = false, glfw_backend_ = false, vulkan_backend_ = false;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
  VkRenderPass pass_ = VK_NULL_HANDLE;
  VkFormat format_ = VK_FORMAT_UNDEFINED;  // the render pass's
  VkImageLayout final_layout_ = VK_IMAGE_LAYOUT_UNDEFINED;  // and its attachment's final layout
  VkExtent2D extent_{0, 0};
  std::vector<VkImage> images_;  // the swapchain's, not owned
  std::vector<VkImageView> views_;
  std::vector<VkFramebuffer> framebuffers_;
  long frames_drawn_ = 0;
  std::unique_ptr<PanelLayer> layer_;  // the shared-memory path's (swapchain_ready with GENERAL)
  long layer_build_ = -1;              // the build the layer holds (-1: none)
  std::optional<std::uint64_t> layer_hash_;  // the drawing it holds (drawing_hash), none: nothing
  long layers_drawn_ = 0;
  // What the last build showed, and whether the user touched the panels since.
  struct Shown {
    session::BrushKind kind{};
    double radius_m = 0, strength = 0, iso = 0, iso_lo = 0, iso_hi = 0;
    WindowLevel wl;
    bool slices = false;
    MaterialsControl materials;
    PanelStats stats;
    bool visible = false;
    bool operator==(const Shown&) const = default;
  };
  std::optional<Shown> shown_;  // none: build the next frame
  bool touched_ = false;
  // Builds still to come after a change: ImGui sizes a new window, and an auto-resized one
  // to new content, from the frame before (a window is hidden in its first frame).
  int settling_ = 0;
  long frames_built_ = 0;
  bool changed(const Shown& now) const;
};

}  // namespace isotouch::sculpt
