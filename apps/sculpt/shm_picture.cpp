#include "isotouch/apps/sculpt/shm_picture.h"

#include <X11/Xlib.h>
#include <X11/Xutil.h>
#include <X11/extensions/XShm.h>
#include <sys/ipc.h>
#include <sys/shm.h>

#include <cerrno>
#include <cstring>
#include <string>

namespace isotouch::sculpt {

using engine::Result;

namespace {
// Errors the server reports for requests made while a trap is set (XShmAttach on a remote
// display: BadAccess), kept instead of Xlib's default handler, which exits the process.
int g_trapped_error = 0;
int trap_error(Display*, XErrorEvent* e) {
  g_trapped_error = e->error_code;
  return 0;
}

/// The window's visual: 24- or 32-bit TrueColor with red 0xff0000, green 0xff00, blue 0xff
/// (a 32-bit pixel's bytes B, G, R, X in memory on a little-endian client).
bool bgrx_visual(Display* d, ::Window w, XWindowAttributes& a, std::string& why) {
  if (!XGetWindowAttributes(d, w, &a)) {
    why = "the window's attributes cannot be read";
    return false;
  }
  const Visual* v = a.visual;
  if ((a.depth != 24 && a.depth != 32) || v->c_class != TrueColor || v->red_mask != 0xff0000 ||
      v->green_mask != 0xff00 || v->blue_mask != 0xff) {
    why = "the window's visual is depth " + std::to_string(a.depth) + ", not 24/32-bit TrueColor BGRX";
    return false;
  }
  return true;
}
}  // namespace

Result<std::unique_ptr<ShmPicture>> ShmPicture::create(_XDisplay* display, unsigned long window, int w, int h) {
  using R = Result<std::unique_ptr<ShmPicture>>;
  Display* d = display;
  if (!d || w <= 0 || h <= 0) return R::fail("no X display or an empty window");
  if (!XShmQueryExtension(d)) return R::fail("the X server offers no MIT-SHM");
  XWindowAttributes a{};
  std::string why;
  if (!bgrx_visual(d, window, a, why)) return R::fail(why);
  std::unique_ptr<ShmPicture> p(new ShmPicture());
  p->display_ = d;
  p->window_ = window;
  p->w_ = w;
  p->h_ = h;
  auto* info = new XShmSegmentInfo{};
  info->shmid = -1;
  info->shmaddr = reinterpret_cast<char*>(-1);
  p->seg_info_ = info;
  p->image_ = XShmCreateImage(d, a.visual, unsigned(a.depth), ZPixmap, nullptr, info, unsigned(w), unsigned(h));
  if (!p->image_ || p->image_->bits_per_pixel != 32) return R::fail("XShmCreateImage made no 32-bit image");
  const std::size_t bytes = std::size_t(p->image_->bytes_per_line) * std::size_t(h);
  info->shmid = shmget(IPC_PRIVATE, bytes, IPC_CREAT | 0600);
  if (info->shmid < 0) return R::fail(std::string("shmget of ") + std::to_string(bytes) + " bytes: " + std::strerror(errno));
  info->shmaddr = static_cast<char*>(shmat(info->shmid, nullptr, 0));
  const int shmat_errno = errno;
  // Marked for removal now: the kernel frees it when both sides detach, even after a crash
  // (Linux lets the server attach a segment so marked while one process still has it).
  shmctl(info->shmid, IPC_RMID, nullptr);
  if (info->shmaddr == reinterpret_cast<char*>(-1)) {
    info->shmid = -1;  // never attached: nothing for the server to detach
    return R::fail(std::string("shmat: ") + std::strerror(shmat_errno));
  }
  p->image_->data = info->shmaddr;
  info->readOnly = False;
  XSync(d, False);
  g_trapped_error = 0;
  XErrorHandler old = XSetErrorHandler(trap_error);
  const Status attached = XShmAttach(d, info);
  XSync(d, False);
  XSetErrorHandler(old);
  if (!attached || g_trapped_error != 0) {
    info->shmid = -1;  // not attached: the destructor only detaches our mapping
    return R::fail("the X server cannot attach the shared memory (a remote display?), error " + std::to_string(g_trapped_error));
  }
  p->gc_ = XCreateGC(d, window, 0, nullptr);
  return R::ok(std::move(p));
}

ShmPicture::~ShmPicture() {
  auto* info = static_cast<XShmSegmentInfo*>(seg_info_);
  if (display_ && info && info->shmid >= 0) {
    XShmDetach(display_, info);
    XSync(display_, False);
  }
  if (gc_) XFreeGC(display_, static_cast<GC>(gc_));
  if (image_) {
    image_->data = nullptr;  // the segment is not Xlib's to free
    XDestroyImage(image_);
  }
  if (info && info->shmaddr != reinterpret_cast<char*>(-1)) shmdt(info->shmaddr);
  delete info;
}

std::uint8_t* ShmPicture::rows() {
  if (pending_) {  // the server has read the segment once it answers a later request
    XSync(display_, False);
    pending_ = false;
  }
  return reinterpret_cast<std::uint8_t*>(image_->data);
}

std::size_t ShmPicture::stride() const { return std::size_t(image_->bytes_per_line); }

void ShmPicture::put() {
  XShmPutImage(display_, window_, static_cast<GC>(gc_), image_, 0, 0, 0, 0, unsigned(w_), unsigned(h_), False);
  XFlush(display_);
  pending_ = true;
}

std::vector<std::uint32_t> ShmPicture::read_window(_XDisplay* display, unsigned long window, int w, int h) {
  std::vector<std::uint32_t> out;
  if (!display || w <= 0 || h <= 0) return out;
  XSync(display, False);
  g_trapped_error = 0;
  XErrorHandler old = XSetErrorHandler(trap_error);
  XImage* img = XGetImage(display, window, 0, 0, unsigned(w), unsigned(h), AllPlanes, ZPixmap);
  XSync(display, False);
  XSetErrorHandler(old);
  if (!img) return out;
  if (img->red_mask == 0xff0000 && img->green_mask == 0xff00 && img->blue_mask == 0xff) {
    out.resize(std::size_t(w) * std::size_t(h));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const unsigned long p = XGetPixel(img, x, y);
        out[std::size_t(y) * std::size_t(w) + std::size_t(x)] =
            std::uint32_t((p >> 16) & 0xff) | std::uint32_t(p & 0xff00) | (std::uint32_t(p & 0xff) << 16) | 0xff000000u;
      }
  }
  XDestroyImage(img);
  return out;
}

}  // namespace isotouch::sculpt
