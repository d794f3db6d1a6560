// igtl_message.h - OpenIGTLink messages in and out, validated before the library touches
// them. Part of isotouch::service.
//
// What arrives on a connection is read one message at a time (read_message): the 58-byte
// header, then the body it announces. Every size is checked against MessageLimits before a
// byte of body is allocated, the CRC-64 is checked by the library, and each kept type's body
// is checked against what its type needs before the library unpacks it (the library reads an
// IMAGE's voxels and a STRING's text past a short body). Kept: IMAGE, TRANSFORM, STRING,
// LBMETA (LABELMETA: which images are label maps); other types are read and skipped. A refusal says why, for the STATUS sent back.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <igtlImageMessage.h>

namespace isotouch::service {

/// Where message bytes come from: a connection (igtl_socket.h) or a buffer (tests, fuzzing).
class ByteSource {
 public:
  virtual ~ByteSource() = default;
  /// Reads exactly `n` bytes into `dst`. `first`: these are the first bytes of a message (a
  /// source may wait for them as long as its connection is open). Returns the bytes read:
  /// fewer than `n` when the source ended, timed out or failed (its why() says which).
  virtual std::size_t read(void* dst, std::size_t n, bool first) = 0;
  /// Why the last short read was short ("connection closed", "nothing for 2 s", ...).
  virtual std::string why() const = 0;
};

/// An IMAGE's size as its 72-byte image header says, before its voxels arrive.
struct ImageSize {
  int dims[3] = {0, 0, 0};         ///< the image's voxels along each axis
  std::uint64_t stored_bytes = 0;  ///< bytes a voxel as sent (scalar size x components)
};

/// MessageLimits::admit_image's answer: the IMAGE refused (`refusal`), or read with what
/// it counts while it lives.
struct AdmittedImage {
  std::string refusal;          ///< "" to read its voxels, else why not
  std::shared_ptr<void> token;  ///< kept in the Incoming (Incoming::held) until it is destroyed
  std::uint64_t bytes = 0;      ///< what the token counts [bytes]
};

/// Bounds on what a message may announce.
struct MessageLimits {
  /// Largest body accepted [bytes]: 512^3 float32 voxels and the IMAGE header.
  std::uint64_t max_body_bytes = std::uint64_t(512) * 512 * 512 * 4 + 72;
  /// Called for an IMAGE once its image header is checked, before its voxels arrive, with
  /// its device name and size: a refusal (its voxels are then read and dropped, never held:
  /// Incoming::kRefused with over_budget set), or a token the Incoming keeps (Incoming::held)
  /// until it is destroyed (a server counts the IMAGEs arriving or held against its memory
  /// budget). Empty: every IMAGE read, nothing held.
  std::function<AdmittedImage(const std::string& device, const ImageSize& size)> admit_image;
};

/// One element of a LBMETA (LABELMETA): a label of the label map IMAGE `image`.
struct LabelMetaEntry {
  std::string name;   ///< the label's name (the element's Name, printable, at most 64 characters)
  std::string image;  ///< the label map IMAGE's device name (the element's DeviceName)
  int label = 0;      ///< its voxel value in that image (0-255)
  std::array<std::uint8_t, 4> rgba{0, 0, 0, 0};  ///< its colour, RGBA 0-255
};

/// One message read from a source.
struct Incoming {
  enum class Kind {
    kImage,      ///< `image` holds it, unpacked (not yet converted: igtl_image.h)
    kTransform,  ///< `matrix` holds it (translation in mm, the sender's frame)
    kString,     ///< `text` holds it
    kLabelMeta,  ///< `labels` holds the device names of the images it describes as label maps
    kSkipped,    ///< a well-formed message of a type not handled here (`type` names it)
    kRefused,    ///< read whole but refused (bad CRC, bad body): `why`; the stream goes on
    kBroken,     ///< the stream cannot go on (closed, timed out, a size past the limits): `why`
    kClosed,     ///< the source ended cleanly between messages
  };
  Kind kind = Kind::kClosed;
  std::string type;    ///< the header's type ("IMAGE", ...), printable
  std::string device;  ///< the header's device name, printable
  std::uint64_t stamp = 0;  ///< the header's time stamp, raw (32.32 fixed-point seconds, the sender's clock)
  std::string why;     ///< kRefused, kBroken: what was wrong, naming the field and value
  igtl::ImageMessage::Pointer image;
  double matrix[4][4] = {};
  std::string text;
  std::vector<std::string> labels;
  std::vector<LabelMetaEntry> label_meta;  ///< kLabelMeta: every element, in the message's order
  /// An IMAGE's: MessageLimits::admit_image's token (null: none) and the bytes it counts.
  std::shared_ptr<void> held;
  std::uint64_t held_bytes = 0;
  /// kRefused by MessageLimits::admit_image (memory, not a malformed message).
  bool over_budget = false;
};

/// Reads and validates the next message from `src`. Never throws for what the bytes say.
Incoming read_message(ByteSource& src, const MessageLimits& limits);

/// A STATUS message (code `code`, e.g. igtl::StatusMessage::STATUS_CONFIG_ERROR) answering
/// the message from `device`, its status string `why` (cut to the protocol's limits),
/// packed for sending.
std::vector<std::uint8_t> pack_status(int code, const std::string& device, const std::string& why);

/// A TRANSFORM message named `device`: rotation identity, translation `t`, time stamped now
/// (or with the raw header stamp `echo` when not 0: the stamp of the message it answers), packed.
std::vector<std::uint8_t> pack_translation(const std::string& device, const double t[3], std::uint64_t echo = 0);

/// Printable form of a fixed-width header field (up to the first NUL, other bytes as '?').
std::string printable(const char* field, std::size_t width);

}  // namespace isotouch::service
