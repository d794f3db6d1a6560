// shm_picture.h - a window's picture handed to a local X server through shared memory
// (MIT-SHM), the way a CPU device's frames reach the screen without the X socket.
//
// On a CPU Vulkan device (lavapipe) the swapchain's present writes the whole image through
// the X socket (XPutImage of 3 MB at 1024x768 in chunks, the client and the server taking
// turns on the CPUs the ray caster needs): 2.5-3.2 ms a frame on the 2-core guest of
// docs/benchmarks.md. Here the server reads the pixels from a segment both map: a memcpy on
// our side and one copy in the server (0.25-0.4 ms for the same frame, a standalone program
// on the same Xvfb). No Vulkan here: window.cpp fills the rows from its own image.
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "isotouch/engine/result.h"

struct _XDisplay;
struct _XImage;

namespace isotouch::sculpt {

class ShmPicture {
 public:
  /// A w x h picture for X window `window` on `display`. Fails (no throw) naming why: the
  /// display offers no MIT-SHM or is remote (the server cannot attach the segment), the
  /// window's visual is not 24- or 32-bit TrueColor with X's B, G, R byte order (the rows'
  /// layout, B8G8R8A8 in memory), or the segment cannot be made.
  static engine::Result<std::unique_ptr<ShmPicture>> create(_XDisplay* display, unsigned long window, int w, int h);
  ~ShmPicture();
  ShmPicture(const ShmPicture&) = delete;
  ShmPicture& operator=(const ShmPicture&) = delete;

  int width() const { return w_; }
  int height() const { return h_; }
  /// The rows to fill (B, G, R, A bytes per pixel, top row first, stride() bytes apart),
  /// once the server has read the last put(): a round trip (XSync) after every put, but by
  /// the next frame the server has long finished that copy, so it answers at once.
  std::uint8_t* rows();
  std::size_t stride() const;
  /// Shows the rows in the window at (0, 0) (XShmPutImage, then a flush: no wait).
  void put();

  /// What the X server holds for `window`'s w x h pixels at (0, 0), as RGBA (R in the low
  /// byte, alpha 255), read back with XGetImage after a round trip (every request before it
  /// done): the picture the user sees, for tests. Empty if the server refuses (e.g. the
  /// window is unmapped) or the visual is not TrueColor 8 bits per channel.
  static std::vector<std::uint32_t> read_window(_XDisplay* display, unsigned long window, int w, int h);

 private:
  ShmPicture() = default;
  _XDisplay* display_ = nullptr;
  unsigned long window_ = 0;
  void* gc_ = nullptr;  // the puts' GC (Xlib's GC)
  _XImage* image_ = nullptr;
  void* seg_info_ = nullptr;  // XShmSegmentInfo, attached
  bool pending_ = false;      // a put the server may still be reading
  int w_ = 0, h_ = 0;
};

}  // namespace isotouch::sculpt
