// libFuzzer target for the OpenIGTLink message handling of `isotouch serve`: any bytes, read
// as a client's stream, give messages that are kept, skipped or refused with a reason, never
// a crash, a read past a body or an exception; a kept IMAGE converts to a volume with finite
// placement and the voxel count its grid says, or is refused with a VolumeError; a kept
// STRING parses to a command or a non-empty reason (commands.h). A kept LBMETA's elements hold
// at most the protocol's field widths and one label byte each; a kept IMAGE read as a label map
// with the LBMETA elements seen so far (serve's label map, label_map.h, on its own grid) gives
// one id per voxel, each a material's or 0, or is refused with a VolumeError.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "isotouch/service/commands.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/service/igtl_message.h"
#include "isotouch/service/label_map.h"

using namespace isotouch;

namespace {

class Bytes final : public service::ByteSource {
 public:
  Bytes(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  std::size_t read(void* dst, std::size_t n, bool) override {
    const std::size_t k = n < n_ - at_ ? n : n_ - at_;
    if (k > 0) std::memcpy(dst, d_ + at_, k);
    at_ += k;
    return k;
  }
  std::string why() const override { return "end of input"; }

 private:
  const std::uint8_t* d_;
  std::size_t n_, at_ = 0;
};

void check_image(igtl::ImageMessage& image) {
  try {
    const engine::Volume v = service::volume_from_image(image);
    if (v.voxels.size() != v.grid.voxel_count()) __builtin_trap();
    const core::Vec3 o = v.grid.origin_m;
    if (!(std::isfinite(o.x) && std::isfinite(o.y) && std::isfinite(o.z))) __builtin_trap();
  } catch (const engine::VolumeError& e) {
    if (std::strlen(e.what()) == 0) __builtin_trap();
  }
}

void check_label_map(igtl::ImageMessage& image, const std::vector<service::LabelMetaEntry>& meta) {
  try {
    const engine::Volume l = service::label_map_from_image(image);
    const materials::LabelVolume lv = service::labels_from_image(l, "fuzz", meta, l, {});
    if (lv.ids.size() != l.grid.voxel_count() || lv.materials.size() != meta.size()) __builtin_trap();
    for (const std::uint8_t id : lv.ids)
      if (id > lv.materials.size()) __builtin_trap();
  } catch (const engine::VolumeError& e) {
    if (std::strlen(e.what()) == 0) __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes src(data, size);
  service::MessageLimits limits;
  limits.max_body_bytes = 1 << 20;
  std::vector<service::LabelMetaEntry> meta;  // the LBMETA elements seen so far
  for (int i = 0; i < 64; ++i) {  // each message takes at least its 58-byte header
    service::Incoming in = service::read_message(src, limits);
    using K = service::Incoming::Kind;
    if (in.kind == K::kClosed || in.kind == K::kBroken) break;
    if (in.kind == K::kRefused && in.why.empty()) __builtin_trap();
    if (in.kind == K::kImage) check_image(*in.image);
    if (in.kind == K::kImage && !meta.empty()) check_label_map(*in.image, meta);
    if (in.kind == K::kLabelMeta) {
      if (in.label_meta.size() != in.labels.size()) __builtin_trap();
      for (const service::LabelMetaEntry& e : in.label_meta)
        if (e.name.size() > 64 || e.image.size() > 20 || e.label < 0 || e.label > 255) __builtin_trap();
      meta = in.label_meta;
    }
    if (in.kind == K::kString) {
      const auto c = service::parse_command(in.text);
      if (const auto* why = std::get_if<std::string>(&c); why && why->empty()) __builtin_trap();
    }
  }
  return 0;
}
