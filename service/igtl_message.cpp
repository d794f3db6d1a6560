#include "isotouch/service/igtl_message.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include <igtlLabelMetaMessage.h>
#include <igtlMessageHeader.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_header.h>
#include <igtl_image.h>
#include <igtl_lbmeta.h>
#include <igtl_transform.h>

namespace isotouch::service {
namespace {

std::uint64_t be(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

int scalar_bytes(int type) {
  switch (type) {
    case igtl::ImageMessage::TYPE_INT8: case igtl::ImageMessage::TYPE_UINT8: return 1;
    case igtl::ImageMessage::TYPE_INT16: case igtl::ImageMessage::TYPE_UINT16: return 2;
    case igtl::ImageMessage::TYPE_INT32: case igtl::ImageMessage::TYPE_UINT32:
    case igtl::ImageMessage::TYPE_FLOAT32: return 4;
    case igtl::ImageMessage::TYPE_FLOAT64: return 8;
    default: return 0;
  }
}

/// "" when an IMAGE body of `n` bytes holds what its own header announces, else why not.
std::string check_image_body(const std::uint8_t* b, std::uint64_t n) {
  std::ostringstream s;
  if (n < IGTL_IMAGE_HEADER_SIZE) {
    s << "IMAGE body of " << n << " bytes is shorter than the image header (" << IGTL_IMAGE_HEADER_SIZE << " bytes)";
    return s.str();
  }
  const int components = b[2], type = b[3], endian = b[4], coord = b[5];
  if (scalar_bytes(type) == 0) return "IMAGE scalar type " + std::to_string(type) + " is not one the protocol defines";
  if (components < 1) return "IMAGE has 0 components";
  if (endian != 1 && endian != 2) return "IMAGE endian " + std::to_string(endian) + " is neither 1 (big) nor 2 (little)";
  if (coord != 1 && coord != 2) return "IMAGE coordinate system " + std::to_string(coord) + " is neither 1 (RAS) nor 2 (LPS)";
  std::uint64_t voxels = 1;
  for (int a = 0; a < 3; ++a) {
    const std::uint64_t size = be(b + 6 + 2 * a, 2), off = be(b + 60 + 2 * a, 2), sub = be(b + 66 + 2 * a, 2);
    if (off + sub > size) {
      s << "IMAGE sub-volume along axis " << a << " (offset " << off << ", size " << sub << ") is past the image's "
        << size << " voxels";
      return s.str();
    }
    voxels *= sub;
  }
  const std::uint64_t want = IGTL_IMAGE_HEADER_SIZE + voxels * std::uint64_t(scalar_bytes(type)) * std::uint64_t(components);
  if (n != want) {
    s << "IMAGE body is " << n << " bytes; its header announces " << want << " (truncated or padded)";
    return s.str();
  }
  return "";
}

/// "" when a body of `n` bytes suits `type` (a kept type), else why not.
std::string check_body(const std::string& type, const std::uint8_t* b, std::uint64_t n) {
  if (type == "IMAGE") return check_image_body(b, n);
  if (type == "TRANSFORM" && n != IGTL_TRANSFORM_SIZE)
    return "TRANSFORM body is " + std::to_string(n) + " bytes, not " + std::to_string(IGTL_TRANSFORM_SIZE);
  if (type == "STRING" && (n < 4 || be(b + 2, 2) + 4 != n))
    return "STRING body of " + std::to_string(n) + " bytes does not hold the length it announces";
  return "";
}

Incoming broken(Incoming in, std::string why) {
  in.kind = Incoming::Kind::kBroken;
  in.why = std::move(why);
  return in;
}

Incoming refused(Incoming in, std::string why) {
  in.kind = Incoming::Kind::kRefused;
  in.why = std::move(why);
  return in;
}

/// Reads and drops `n` bytes (a type not handled here). False if the source ran short.
bool skip(ByteSource& src, std::uint64_t n) {
  std::vector<std::uint8_t> scratch(std::size_t(std::min<std::uint64_t>(n, 1 << 16)));
  while (n > 0) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(n, scratch.size()));
    if (src.read(scratch.data(), k, false) != k) return false;
    n -= k;
  }
  return true;
}

constexpr std::uint64_t kMaxLabelBytes = std::uint64_t(IGTL_LBMETA_ELEMENT_SIZE) * 4096;

/// "" when a kept type's body of `n` bytes can be read at all, judged from the message
/// header alone (TRANSFORM's size is fixed, STRING's text is at most 65535 bytes).
std::string check_size(const std::string& type, std::uint64_t n) {
  if (type == "TRANSFORM" && n != IGTL_TRANSFORM_SIZE)
    return "TRANSFORM body is " + std::to_string(n) + " bytes, not " + std::to_string(IGTL_TRANSFORM_SIZE);
  if (type == "STRING" && (n < 4 || n > 4 + 0xFFFF))
    return "STRING body of " + std::to_string(n) + " bytes cannot hold a 16-bit length and its text";
  if (type == "LBMETA" && (n % IGTL_LBMETA_ELEMENT_SIZE != 0 || n > kMaxLabelBytes))
    return "LBMETA body of " + std::to_string(n) + " bytes is not a whole number of " +
           std::to_string(IGTL_LBMETA_ELEMENT_SIZE) + "-byte labels (at most " + std::to_string(kMaxLabelBytes) + " bytes)";
  return "";
}

/// Reads a body of `n` bytes into `body` (which may already hold its first bytes), growing
/// the buffer as bytes arrive so that a body announced but not sent costs no memory.
bool read_growing(ByteSource& src, std::vector<std::uint8_t>& body, std::uint64_t n) {
  constexpr std::size_t kChunk = std::size_t(1) << 20;
  while (body.size() < n) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, n - body.size()));
    const std::size_t at = body.size();
    body.resize(at + k);
    if (src.read(body.data() + at, k, false) != k) return false;
  }
  return true;
}

/// Reads the body of a kept message into `body`, checked before the whole of it is
/// allocated: sizes from the message header, an IMAGE's voxel count from its 72-byte image
/// header, then `before_growing` on that header (an IMAGE's: "" to read its voxels, else why
/// it is refused). "" when read and acceptable; else why not (`truncated`: the stream
/// cannot go on); a refused body is read and dropped, never held.
std::string read_body(ByteSource& src, const std::string& type, std::uint64_t n, std::vector<std::uint8_t>& body,
                      bool& truncated, const std::function<std::string(const std::uint8_t*)>& before_growing) {
  truncated = false;
  const std::uint64_t first = type == "IMAGE" ? std::min<std::uint64_t>(n, IGTL_IMAGE_HEADER_SIZE) : 0;
  std::string why = check_size(type, n);
  if (why.empty() && first > 0) {
    body.resize(std::size_t(first));
    if (src.read(body.data(), body.size(), false) != body.size()) return truncated = true, type + " body truncated: " + src.why();
    if (first == IGTL_IMAGE_HEADER_SIZE) why = check_image_body(body.data(), n);  // only the header is read
    if (why.empty() && first == IGTL_IMAGE_HEADER_SIZE && before_growing) why = before_growing(body.data());
  }
  if (!why.empty()) {  // refused: the rest is read and dropped so that the stream goes on
    if (!skip(src, n - body.size())) return truncated = true, type + " body truncated: " + src.why();
    return why;
  }
  if (!read_growing(src, body, n)) return truncated = true, type + " body truncated: " + src.why();
  return check_body(type, body.data(), n);
}

/// The kept message of `header`'s type, its body read from `src` and checked; unpacked.
Incoming read_kept(ByteSource& src, igtl::MessageHeader* header, Incoming in, std::uint64_t body_bytes,
                   const MessageLimits& limits) {
  igtl::MessageBase::Pointer msg;
  igtl::ImageMessage::Pointer image;
  igtl::TransformMessage::Pointer transform;
  igtl::StringMessage::Pointer text;
  igtl::LabelMetaMessage::Pointer labels;
  if (in.type == "LBMETA") msg = labels = igtl::LabelMetaMessage::New();
  if (in.type == "IMAGE") msg = image = igtl::ImageMessage::New();
  if (in.type == "TRANSFORM") msg = transform = igtl::TransformMessage::New();
  if (in.type == "STRING") msg = text = igtl::StringMessage::New();
  // The body is read into a buffer and checked before the library sees it (its
  // AllocatePack() sizes an IMAGE by what the message itself holds, not by the header's
  // body size).
  std::vector<std::uint8_t> body;
  bool truncated = false;
  std::function<std::string(const std::uint8_t*)> hold;
  if (image && limits.admit_image)
    hold = [&](const std::uint8_t* h) -> std::string {
      ImageSize size;
      for (int a = 0; a < 3; ++a) size.dims[a] = int(be(h + 6 + 2 * a, 2));
      size.stored_bytes = std::uint64_t(scalar_bytes(h[3])) * std::uint64_t(h[2]);
      AdmittedImage a = limits.admit_image(in.device, size);
      if (!a.refusal.empty()) return in.over_budget = true, a.refusal;
      in.held = std::move(a.token);
      in.held_bytes = a.bytes;
      return "";
    };
  if (std::string why = read_body(src, in.type, body_bytes, body, truncated, hold); !why.empty()) {
    in.over_budget = in.over_budget && !truncated;
    return truncated ? broken(in, why) : refused(in, why);
  }
  msg->SetMessageHeader(header);
  msg->AllocatePack();
  if (std::uint64_t(msg->GetPackBodySize()) != body_bytes)
    return refused(in, in.type + " body of " + std::to_string(body_bytes) + " bytes: the library allocated " +
                           std::to_string(msg->GetPackBodySize()));
  if (!body.empty()) std::memcpy(msg->GetPackBodyPointer(), body.data(), body.size());  // an empty LBMETA: no pointer
  std::vector<std::uint8_t>().swap(body);  // one copy held, the library's
  if (!(msg->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) return refused(in, in.type + " body fails its CRC-64");
  if (image) {
    in.kind = Incoming::Kind::kImage;
    in.image = image;
  } else if (transform) {
    igtl::Matrix4x4 m;
    transform->GetMatrix(m);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) in.matrix[r][c] = m[r][c];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c)
        if (!std::isfinite(in.matrix[r][c])) return refused(in, "TRANSFORM holds a value that is not finite");
    in.kind = Incoming::Kind::kTransform;
  } else if (labels) {
    in.kind = Incoming::Kind::kLabelMeta;
    for (int i = 0; i < labels->GetNumberOfLabelMetaElement(); ++i) {
      igtl::LabelMetaElement::Pointer e;
      labels->GetLabelMetaElement(i, e);
      const std::string name = e->GetDeviceName();
      in.labels.push_back(printable(name.c_str(), std::min<std::size_t>(name.size(), IGTL_LBMETA_LEN_DEVICE_NAME)));
      const std::string label_name = e->GetName();
      LabelMetaEntry entry;
      entry.name = printable(label_name.c_str(), std::min<std::size_t>(label_name.size(), IGTL_LBMETA_LEN_NAME));
      entry.image = in.labels.back();
      entry.label = int(e->GetLabel());
      e->GetRGBA(entry.rgba.data());
      in.label_meta.push_back(std::move(entry));
    }
  } else {
    in.kind = Incoming::Kind::kString;
    in.text = text->GetString();
  }
  return in;
}

}  // namespace

std::string printable(const char* field, std::size_t width) {
  std::string s;
  for (std::size_t i = 0; i < width && field[i] != '\0'; ++i)
    s += (field[i] >= 32 && field[i] < 127) ? field[i] : '?';
  return s;
}

Incoming read_message(ByteSource& src, const MessageLimits& limits) {
  Incoming in;
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  auto* h = static_cast<std::uint8_t*>(header->GetPackPointer());
  const std::size_t got = src.read(h, IGTL_HEADER_SIZE, true);
  if (got == 0) return in;  // kClosed
  if (got != IGTL_HEADER_SIZE) return broken(in, "header truncated after " + std::to_string(got) + " bytes: " + src.why());
  in.type = printable(reinterpret_cast<const char*>(h + 2), IGTL_HEADER_TYPE_SIZE);
  in.device = printable(reinterpret_cast<const char*>(h + 14), IGTL_HEADER_NAME_SIZE);
  const std::uint64_t version = be(h, 2), body_bytes = be(h + 42, 8);
  in.stamp = be(h + 34, 8);
  if (body_bytes > limits.max_body_bytes)
    return broken(in, in.type + " body of " + std::to_string(body_bytes) + " bytes is past the limit of " +
                          std::to_string(limits.max_body_bytes) + " bytes");
  const bool kept = in.type == "IMAGE" || in.type == "TRANSFORM" || in.type == "STRING" || in.type == "LBMETA";
  if (!kept || version < 1 || version > 2) {
    if (!skip(src, body_bytes)) return broken(in, in.type + " body truncated: " + src.why());
    if (version < 1 || version > 2)
      return refused(in, "header version " + std::to_string(version) + " is not 1 or 2 (OpenIGTLink 1.11)");
    in.kind = Incoming::Kind::kSkipped;
    return in;
  }
  header->Unpack();
  return read_kept(src, header, in, body_bytes, limits);
}

std::vector<std::uint8_t> pack_status(int code, const std::string& device, const std::string& why) {
  igtl::StatusMessage::Pointer s = igtl::StatusMessage::New();
  s->SetDeviceName(device.substr(0, IGTL_HEADER_NAME_SIZE).c_str());
  s->SetCode(code);
  s->SetSubCode(0);
  s->SetErrorName("isotouch");
  s->SetStatusString(why.substr(0, 1000).c_str());
  s->Pack();
  const auto* p = static_cast<const std::uint8_t*>(s->GetPackPointer());
  return {p, p + s->GetPackSize()};
}

std::vector<std::uint8_t> pack_translation(const std::string& device, const double t[3], std::uint64_t echo) {
  igtl::TransformMessage::Pointer m = igtl::TransformMessage::New();
  m->SetDeviceName(device.substr(0, IGTL_HEADER_NAME_SIZE).c_str());
  igtl::Matrix4x4 x;
  igtl::IdentityMatrix(x);
  for (int r = 0; r < 3; ++r) x[r][3] = float(t[r]);
  m->SetMatrix(x);
  igtl::TimeStamp::Pointer now = igtl::TimeStamp::New();
  now->GetTime();  // the receiver can measure the rate
  m->SetTimeStamp(now);
  m->Pack();
  const auto* p = static_cast<const std::uint8_t*>(m->GetPackPointer());
  std::vector<std::uint8_t> out(p, p + m->GetPackSize());
  for (int i = 0; echo != 0 && i < 8; ++i) out[std::size_t(34 + i)] = std::uint8_t(echo >> (8 * (7 - i)));  // not in the CRC
  return out;
}

}  // namespace isotouch::service
