// The OpenIGTLink service's message layer: messages built by the OpenIGTLink library (the
// sender's side, as Slicer or PLUS would build them) read back through read_message, the
// IMAGE -> volume conversion against loading the file, refusals, deadlines, dead peers.
#include <gtest/gtest.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <thread>
#include <unordered_map>

#include <igtlImageMessage.h>
#include <igtlLabelMetaMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>

#include "isotouch/service/commands.h"
#include "isotouch/service/edit_mirror.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/service/image_isovalue.h"
#include "isotouch/service/registration.h"
#include "isotouch/service/igtl_message.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/transform_device.h"
#include "isotouch/tests/igtl_test_sender.h"
#include "isotouch/tests/memory_source.h"
#include "isotouch/tests/temp_dir.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::service {
namespace {
using test::bytes_of;
using test::image_of;

const std::string kHead = std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd";

using test::MemorySource;

engine::Volume received_volume(std::vector<std::uint8_t> bytes) {
  MemorySource src(std::move(bytes));
  Incoming in = read_message(src, MessageLimits{});
  EXPECT_EQ(in.kind, Incoming::Kind::kImage) << in.why;
  if (in.kind != Incoming::Kind::kImage) return {};
  return volume_from_image(*in.image);
}

/// Same voxels, and the 8 corner voxel centres in the same physical place within 1e-6 m.
void expect_same_place(const engine::Volume& file, const engine::Volume& got) {
  ASSERT_EQ(got.grid.dims, file.grid.dims);
  ASSERT_EQ(got.voxels.size(), file.voxels.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < file.voxels.size(); ++i) differ += got.voxels[i] != file.voxels[i];
  EXPECT_EQ(differ, 0u);
  for (int k = 0; k < 8; ++k) {
    const core::Vec3 idx{k & 1 ? file.grid.dims[0] - 1.0 : 0.0, k & 2 ? file.grid.dims[1] - 1.0 : 0.0,
                         k & 4 ? file.grid.dims[2] - 1.0 : 0.0};
    const core::Vec3 a = file.index_to_physical(idx), b = got.index_to_physical(idx);
    EXPECT_LE(core::norm(a - b), 1e-6) << "corner " << k << ": file (" << a.x << ", " << a.y << ", " << a.z
                                       << ") received (" << b.x << ", " << b.y << ", " << b.z << ")";
  }
}

/// The shipped head's voxels under a rotated direction and an offset (a .mhd written beside
/// them): the centre, the RAS flip and the direction all show in the corners.
engine::Volume rotated_head() {
  test::TempDir dir("isotouch-igtl");
  const auto mhd = dir.path / "rotated.mhd";
  std::ofstream(mhd) << "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                     << "TransformMatrix = 0 1 0 -0.6 0 0.8 0.8 0 0.6\nOffset = 12.5 -40 7\n"
                     << "ElementSpacing = 3.2 3.2 1.5\nDimSize = 64 64 93\nElementType = MET_SHORT\n"
                     << "ElementDataFile = " << std::string(ISOTOUCH_TEST_DATA)
                     << "/ct-head-headsq/headsq_64x64x93_int16.raw\n";
  return io::load_volume(mhd.string());
}

TEST(ServiceImage, ShippedHeadLandsWhereTheFileDoes) {
  const engine::Volume file = io::load_volume(kHead);
  expect_same_place(file, received_volume(image_of(file, igtl::ImageMessage::ENDIAN_BIG)));
  expect_same_place(file, received_volume(image_of(file, igtl::ImageMessage::ENDIAN_LITTLE)));
}

TEST(ServiceImage, RotatedAndShiftedHeadLandsWhereTheFileDoes) {
  // The same voxels under a rotated direction and an offset: the centre, the RAS flip and
  // the direction all show in the corners.
  const engine::Volume file = rotated_head();
  ASSERT_FALSE(file.direction_is_identity);
  expect_same_place(file, received_volume(image_of(file, igtl::ImageMessage::ENDIAN_LITTLE)));
}

TEST(ServiceImage, SingleSliceIsRefusedSayingWhy) {
  // What the upstream Imager examples send: 256 x 256 x 1 uint8.
  MemorySource src(test::single_slice());
  Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kImage) << in.why;
  try {
    volume_from_image(*in.image);
    FAIL() << "a single slice was taken as a volume";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find("single slice"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("256 x 256 x 1"), std::string::npos) << e.what();
  }
}

TEST(ServiceImage, LabelMapIsRefused) {
  const engine::Volume file = io::load_volume(kHead);
  MemorySource src(image_of(file, igtl::ImageMessage::ENDIAN_BIG, "HeadLabelMap"));
  Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kImage);
  EXPECT_THROW(volume_from_image(*in.image), engine::VolumeError);
}

std::vector<std::uint8_t> transform_bytes(const char* name, float x, float y, float z) {
  igtl::TransformMessage::Pointer t = igtl::TransformMessage::New();
  t->SetDeviceName(name);
  igtl::Matrix4x4 m;
  igtl::IdentityMatrix(m);
  m[0][3] = x;
  m[1][3] = y;
  m[2][3] = z;
  t->SetMatrix(m);
  return bytes_of(t);
}

TEST(ServiceMessages, TransformStringAndUnknownTypes) {
  std::vector<std::uint8_t> all = transform_bytes("StylusToTracker", 1.5f, -2, 30);
  igtl::StatusMessage::Pointer s = igtl::StatusMessage::New();  // not a kept type: skipped
  s->SetDeviceName("X");
  s->SetStatusString("hello");
  const auto sb = bytes_of(s);
  all.insert(all.end(), sb.begin(), sb.end());
  igtl::StringMessage::Pointer str = igtl::StringMessage::New();
  str->SetDeviceName("CMD");
  str->SetString("isovalue 500");
  const auto tb = bytes_of(str);
  all.insert(all.end(), tb.begin(), tb.end());
  MemorySource src(all);
  Incoming a = read_message(src, MessageLimits{});
  ASSERT_EQ(a.kind, Incoming::Kind::kTransform) << a.why;
  EXPECT_EQ(a.device, "StylusToTracker");
  EXPECT_DOUBLE_EQ(a.matrix[0][3], 1.5);
  EXPECT_DOUBLE_EQ(a.matrix[1][3], -2);
  EXPECT_DOUBLE_EQ(a.matrix[2][3], 30);
  Incoming b = read_message(src, MessageLimits{});
  EXPECT_EQ(b.kind, Incoming::Kind::kSkipped);
  EXPECT_EQ(b.type, "STATUS");
  Incoming c = read_message(src, MessageLimits{});
  ASSERT_EQ(c.kind, Incoming::Kind::kString) << c.why;
  EXPECT_EQ(c.text, "isovalue 500");
  EXPECT_EQ(read_message(src, MessageLimits{}).kind, Incoming::Kind::kClosed);
}

/// `bytes` hold a message to refuse (its reason containing `why`) followed by
/// transform_bytes("T", 4, 5, 6): the refusal does not lose the stream.
void expect_refused_then_the_next(const std::vector<std::uint8_t>& bytes, const std::string& why) {
  MemorySource src(bytes);
  Incoming a = read_message(src, MessageLimits{});
  EXPECT_EQ(a.kind, Incoming::Kind::kRefused);
  EXPECT_NE(a.why.find(why), std::string::npos) << a.why;
  Incoming b = read_message(src, MessageLimits{});
  ASSERT_EQ(b.kind, Incoming::Kind::kTransform) << b.why;
  EXPECT_DOUBLE_EQ(b.matrix[2][3], 6);
}

TEST(ServiceMessages, WrongCrcIsRefusedAndTheStreamGoesOn) {
  std::vector<std::uint8_t> all = transform_bytes("T", 1, 2, 3);
  all[58 + 5] ^= 0x40;  // a body byte: the CRC no longer matches
  const auto next = transform_bytes("T", 4, 5, 6);
  all.insert(all.end(), next.begin(), next.end());
  expect_refused_then_the_next(all, "CRC");
}

TEST(ServiceMessages, TruncatedAndOversizedBodiesAreRefused) {
  std::vector<std::uint8_t> t = transform_bytes("T", 1, 2, 3);
  t.resize(t.size() - 10);
  MemorySource cut(t);
  Incoming a = read_message(cut, MessageLimits{});
  EXPECT_EQ(a.kind, Incoming::Kind::kBroken);
  EXPECT_NE(a.why.find("truncated"), std::string::npos) << a.why;

  const engine::Volume file = io::load_volume(kHead);
  MessageLimits small;
  small.max_body_bytes = 1000;
  MemorySource big(image_of(file, igtl::ImageMessage::ENDIAN_BIG));
  Incoming b = read_message(big, small);
  EXPECT_EQ(b.kind, Incoming::Kind::kBroken);
  EXPECT_NE(b.why.find("past the limit of 1000"), std::string::npos) << b.why;

  // An IMAGE whose own header announces more voxels than its body holds (the body size and
  // CRC consistent): the library would read past the body.
  std::vector<std::uint8_t> img = image_of(file, igtl::ImageMessage::ENDIAN_BIG);
  img[58 + 6 + 1] = 65;  // size along x: 64 -> 65
  img[58 + 66 + 1] = 65;  // and the sub-volume with it
  MemorySource lie(img);
  Incoming c = read_message(lie, MessageLimits{});
  EXPECT_EQ(c.kind, Incoming::Kind::kRefused);
  EXPECT_NE(c.why.find("announces"), std::string::npos) << c.why;
}

TEST(ServiceMessages, StatusCarriesTheReason) {
  const auto b = pack_status(igtl::StatusMessage::STATUS_CONFIG_ERROR, "ImagerClient", "a single slice");
  igtl::StatusMessage::Pointer s = igtl::StatusMessage::New();
  s->AllocatePack();
  std::memcpy(s->GetPackPointer(), b.data(), 58);
  s->Unpack();
  s->AllocatePack();
  std::memcpy(s->GetPackBodyPointer(), b.data() + 58, b.size() - 58);
  ASSERT_TRUE(s->Unpack(1) & igtl::MessageHeader::UNPACK_BODY);
  EXPECT_EQ(s->GetCode(), igtl::StatusMessage::STATUS_CONFIG_ERROR);
  EXPECT_STREQ(s->GetStatusString(), "a single slice");
  EXPECT_STREQ(s->GetDeviceName(), "ImagerClient");
}

TEST(ServiceSocket, TruncatedBodyEndsAtTheReceiveTimeout) {
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  std::vector<std::uint8_t> t = transform_bytes("T", 1, 2, 3);
  ASSERT_EQ(::write(sv[1], t.data(), t.size() - 20), ssize_t(t.size() - 20));  // and then nothing
  std::atomic<bool> stop{false};
  Connection c(sv[0], 300, 60000, &stop);
  const auto t0 = std::chrono::steady_clock::now();
  Incoming in = read_message(c, MessageLimits{});
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(in.kind, Incoming::Kind::kBroken);
  EXPECT_NE(in.why.find("nothing for 300 ms"), std::string::npos) << in.why;
  EXPECT_LT(s, 2.0);
  ::close(sv[1]);
}

TEST(ServiceSocket, SendToADeadPeerFailsWithoutSigpipe) {
  // SIGPIPE's default action would end this test process.
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  ::close(sv[1]);
  Connection c(sv[0], 300, 60000, nullptr);
  const auto b = transform_bytes("T", 1, 2, 3);
  EXPECT_FALSE(c.send(b));
  EXPECT_FALSE(c.alive());
}

}  // namespace
}  // namespace isotouch::service

namespace isotouch::service {
namespace {

TEST(ServiceMessages, ImageBodyPastTheLibrarysBufferIsRefused) {
  // Found by fuzz_igtl: an IMAGE whose image header the library sizes differently from the
  // message header's body size; reading the body into the library's buffer overflowed it.
  std::ifstream f(std::string(ISOTOUCH_TEST_SOURCE) + "/fuzz/corpus_igtl/image_body_past_library_buffer", std::ios::binary);
  std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_GT(b.size(), 58u);
  MemorySource src(b);
  Incoming in = read_message(src, MessageLimits{});
  EXPECT_EQ(in.kind, Incoming::Kind::kRefused) << in.why;
  EXPECT_FALSE(in.why.empty());
  std::cout << "refused: " << in.why << "\n";
}

}  // namespace
}  // namespace isotouch::service

namespace isotouch::service {
namespace {

TEST(ServiceDevice, StreamPointsAndForcesInTheVolumesFrames) {
  // A rotated volume: RAS mm + offset -> LPS m -> grid frame, and the force back to RAS.
  engine::Volume v;
  v.grid.dims = {4, 4, 4};
  v.grid.spacing_m = {1e-3, 2e-3, 3e-3};
  v.grid.origin_m = {0.01, -0.02, 0.03};
  v.direction = {0, -1, 0, 1, 0, 0, 0, 0, 1};  // row-major: index x -> LPS +y (posterior), index y -> LPS -x
  v.direction_is_identity = false;
  TransformDevice d;
  d.set_frame(v, {5, 6, 7});
  EXPECT_EQ(d.read().received_ns, 1) << "before any TRANSFORM the reading must be old (stale)";
  const double t[3] = {10, 20, 30};  // RAS mm
  d.push_mm(t);
  const servo::DeviceReading r = d.read();
  EXPECT_GT(r.received_ns, 1);
  const core::Vec3 lps{-(10 + 5) * 1e-3, -(20 + 6) * 1e-3, (30 + 7) * 1e-3};
  EXPECT_LE(core::norm(v.to_physical(r.position_m) - lps), 1e-12);
  // A force along grid +x is LPS (0, +2, 0) = RAS (0, -2, 0).
  d.write_force_n({2, 0, 0});
  const core::Vec3 f = d.force_ras_n(0.5);
  EXPECT_NEAR(f.x, 0, 1e-12);
  EXPECT_NEAR(f.y, -2, 1e-12);
  EXPECT_NEAR(f.z, 0, 1e-12);
  // The servo stopped writing: after the stall time the force sent is zero.
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  EXPECT_EQ(core::norm(d.force_ras_n(0.02)), 0.0);
  // The HIP sent out: grid -> RAS mm, the inverse of the stream's mapping (offset aside).
  const core::Vec3 ras = d.grid_to_ras_mm(r.position_m);
  EXPECT_NEAR(ras.x, 15, 1e-9);
  EXPECT_NEAR(ras.y, 26, 1e-9);
  EXPECT_NEAR(ras.z, 37, 1e-9);
}

// The poses the servo never read are counted once each, when a newer pose replaces them, by
// how soon it came: pushed 1-2 read, 3-4-5 pushed with one read after 5: poses 3 and 4 were
// never read; pose 5, read, and pose 6, pushed last and not read yet, are not counted.
/// A device streaming into a 4^3 volume of 1 mm voxels, no offset.
void set_unit_frame(TransformDevice& d) {
  engine::Volume v;
  v.grid.dims = {4, 4, 4};
  v.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  d.set_frame(v, {0, 0, 0});
}

TEST(ServiceDevice, EachPoseNeverReadIsCountedOnce) {
  TransformDevice d;
  set_unit_frame(d);
  const double t[3] = {1, 2, 3};
  d.push_mm(t), d.read(), d.push_mm(t), d.read();
  d.push_mm(t), d.push_mm(t), d.push_mm(t), d.read(), d.read();
  d.push_mm(t);
  EXPECT_EQ(d.overtaken(), 2);
  long binned = 0;
  for (long g : d.overtaken_gaps()) binned += g;
  EXPECT_EQ(binned, 2) << "the gaps' table counts other poses than overtaken()";
}

// The servo's wait for a late pose ends when the arrival clock moves on
// (ServoThread::wait_for_input), and the tick then reads the pose: it must be there by then,
// or the tick reads the one before and the late pose is overtaken by the next. A thread
// pushes a pose every 50 us and notes the predicted arrival each push left; this thread
// watches the clock as the servo does and, each time the prediction moves, reads the pose.
// Afterwards each prediction seen is matched to the push that made it: the pose read then
// must be that push's or a newer one.
TEST(ServiceDevice, APoseIsReadableOnceItsArrivalMovedTheClock) {
  TransformDevice d;
  set_unit_frame(d);
  constexpr int kPushes = 60000;
  std::vector<std::int64_t> due_after(kPushes);  // the pusher's; read after it joined
  std::atomic<bool> done{false};
  std::thread pusher([&] {
    const double t[3] = {1, 2, 3};
    for (int i = 0; i < kPushes; ++i) {
      const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(50);
      d.push_mm(t, std::uint64_t(i) + 1);
      due_after[std::size_t(i)] = d.input_phase().due_ns;  // the only writer of the clock: push i's
      while (std::chrono::steady_clock::now() < until) {
      }
    }
    done = true;
  });
  std::vector<std::pair<std::int64_t, std::uint64_t>> seen;  // (prediction, the pose's sequence then)
  seen.reserve(std::size_t(kPushes) + 1);
  std::int64_t due = d.input_phase().due_ns;
  while (!done && seen.size() < seen.capacity()) {
    const std::int64_t now_due = d.input_phase().due_ns;
    if (now_due == due) continue;
    due = now_due;
    // The pose as a waiting reader sees it (read() also gives up on a store preempted midway,
    // keeping its last pose: another rule, LatestValue's).
    if (now_due >= 0) seen.emplace_back(now_due, d.newest_pose().sequence);
  }
  pusher.join();
  std::unordered_map<std::int64_t, std::uint64_t> push_of;  // prediction -> the first push (sequence) that made it
  for (int i = kPushes - 1; i >= 0; --i)
    if (due_after[std::size_t(i)] >= 0) push_of[due_after[std::size_t(i)]] = std::uint64_t(i) + 1;
  long matched = 0, behind = 0;
  for (const auto& [prediction, sequence] : seen) {
    const auto it = push_of.find(prediction);
    if (it == push_of.end()) continue;
    ++matched;
    behind += sequence < it->second;
  }
  std::printf("the prediction moved %zu times seen (%ld matched); the pose read was older than its push %ld times\n",
              seen.size(), matched, behind);
  EXPECT_GT(matched, 100) << "the clock never had a prediction";
  EXPECT_EQ(behind, 0) << "the arrival clock moved before its pose could be read";
}

// The tracker registered to the image by a rotation (90 degrees about S: tracker +R is image
// +A, tracker +A is image -R) and a translation (10, 20, 30) mm, worked out by hand: the
// pose (1, 2, 3) lands at image (-2 + 10, 1 + 20, 3 + 30) = (8, 21, 33), plus the offset
// (5, 6, 7); a force of image RAS (0, -2, 0) goes back to the tracker as (-2, 0, 0) (R^T).
TEST(ServiceDevice, ARotatedRegistrationMapsPosesAndForcesBack) {
  engine::Volume v;
  v.grid.dims = {4, 4, 4};
  v.grid.spacing_m = {1e-3, 2e-3, 3e-3};
  v.grid.origin_m = {0.01, -0.02, 0.03};
  v.direction = {0, -1, 0, 1, 0, 0, 0, 0, 1};
  v.direction_is_identity = false;
  TransformDevice d;
  d.set_frame(v, {5, 6, 7});
  const double m[4][4] = {{0, -1, 0, 10}, {1, 0, 0, 20}, {0, 0, 1, 30}, {0, 0, 0, 1}};
  d.set_registration(registration_from_matrix(m));
  const double t[3] = {1, 2, 3};  // tracker RAS mm
  d.push_mm(t);
  const core::Vec3 ras = d.grid_to_ras_mm(d.read().position_m);
  EXPECT_NEAR(ras.x, 8 + 5, 1e-9);
  EXPECT_NEAR(ras.y, 21 + 6, 1e-9);
  EXPECT_NEAR(ras.z, 33 + 7, 1e-9);
  d.write_force_n({2, 0, 0});  // grid +x: image RAS (0, -2, 0) (the test above)
  const core::Vec3 f = d.to_tracker_n(d.force_ras_n(0.5));
  EXPECT_NEAR(f.x, -2, 1e-12);
  EXPECT_NEAR(f.y, 0, 1e-12);
  EXPECT_NEAR(f.z, 0, 1e-12);
}

// Only rigid registrations are taken (a scale, a mirror, a last row other than 0 0 0 1 are
// refused naming why); a file holds the 4x4 row by row, 12 numbers without the last row.
TEST(ServiceDevice, RegistrationsAreRigidAndReadFromAFile) {
  const double scaled[4][4] = {{2, 0, 0, 0}, {0, 2, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 1}};
  const double mirror[4][4] = {{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
  const double row[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 1, 1}};
  for (const auto* m : {scaled, mirror})
    try {
      registration_from_matrix(m);
      ADD_FAILURE() << "a scale or mirror was taken as a registration";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("not rigid"), std::string::npos) << e.what();
    }
  EXPECT_THROW(registration_from_matrix(row), std::invalid_argument);
  const test::TempDir dir("isotouch-registration");
  const std::string file = (dir.path / "r.txt").string();
  std::ofstream(file) << "# 90 degrees about R, then 5 mm along S\n1 0 0 0\n0 0 -1 0\n0, 1, 0, 5\n";
  const Registration r = load_registration(file);
  const core::Vec3 p = r.to_image_mm({0, 1, 0});  // tracker +A -> image +S
  EXPECT_NEAR(p.x, 0, 1e-12);
  EXPECT_NEAR(p.y, 0, 1e-12);
  EXPECT_NEAR(p.z, 6, 1e-12);
  std::ofstream(file) << "1 0 0\n";
  EXPECT_THROW(load_registration(file), std::runtime_error);
}

}  // namespace
}  // namespace isotouch::service

namespace isotouch::service {
namespace {

/// A message header of `type` announcing `body_bytes`, followed by `body` (maybe short of it).
std::vector<std::uint8_t> announced(const char* type, std::uint64_t body_bytes, std::vector<std::uint8_t> body = {}) {
  std::vector<std::uint8_t> b(58 + body.size(), 0);
  std::copy(body.begin(), body.end(), b.begin() + 58);
  b[1] = 1;  // version 1
  std::memcpy(b.data() + 2, type, std::strlen(type));
  std::memcpy(b.data() + 14, "Big", 3);
  for (int i = 0; i < 8; ++i) b[42 + i] = std::uint8_t(body_bytes >> (8 * (7 - i)));
  return b;
}

/// What read_message made of `bytes` in a child process whose address space is capped at
/// `cap_mib` above what it already maps: the kind (as an int), or -1 when the child died.
int kind_under_address_cap(const std::vector<std::uint8_t>& bytes, std::uint64_t cap_mib) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::ifstream st("/proc/self/statm");
    std::uint64_t pages = 0;
    st >> pages;
    const rlimit lim{pages * std::uint64_t(::sysconf(_SC_PAGESIZE)) + (cap_mib << 20), RLIM_INFINITY};
    ::setrlimit(RLIMIT_AS, &lim);
    try {
      MemorySource src(bytes);
      _exit(int(read_message(src, MessageLimits{}).kind));
    } catch (...) {
      _exit(100);
    }
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(ServiceMemory, AnnouncedBodiesAreNotAllocatedBeforeTheyArrive) {
  // 512 MiB announced, nothing (or only a valid image header) sent: with 64 MiB of address
  // space to spare, a reader that allocates the announced body up front throws bad_alloc.
  const std::uint64_t big = MessageLimits{}.max_body_bytes;
  EXPECT_EQ(kind_under_address_cap(announced("TRANSFORM", big), 64), int(Incoming::Kind::kBroken))
      << "TRANSFORM of 512 MiB: the child did not end with the stream broken (100: threw, -1: died)";
  EXPECT_EQ(kind_under_address_cap(announced("STRING", big), 64), int(Incoming::Kind::kBroken));
  // An IMAGE header announcing 512^3 float32 voxels, its body never sent.
  std::vector<std::uint8_t> ih(72, 0);
  ih[1] = 1;  // image header version
  ih[2] = 1;  // components
  ih[3] = igtl::ImageMessage::TYPE_FLOAT32;
  ih[4] = 2;
  ih[5] = 1;
  for (int a = 0; a < 3; ++a) ih[6 + 2 * a] = ih[66 + 2 * a] = 2;  // 512 = 0x0200
  EXPECT_EQ(kind_under_address_cap(announced("IMAGE", big, ih), 64), int(Incoming::Kind::kBroken))
      << "IMAGE of 512 MiB announced, only its header sent";
  // The same cap still takes a real head (64 x 64 x 93 int16).
  const engine::Volume file = io::load_volume(kHead);
  EXPECT_EQ(kind_under_address_cap(image_of(file, igtl::ImageMessage::ENDIAN_BIG), 64), int(Incoming::Kind::kImage));
}

// MessageLimits::admit_image (serve's one memory budget): an IMAGE is admitted from its
// checked image header (its dims and bytes a voxel as the header says) and held until its
// Incoming is gone; an IMAGE cut short holds until the broken Incoming goes; a TRANSFORM
// holds nothing.
TEST(ServiceMemory, AnImagesBodyIsHeldWhileItsIncomingLives) {
  std::uint64_t held = 0;
  std::vector<std::string> devices;
  MessageLimits limits;
  const std::uint64_t body = 72 + std::uint64_t(64) * 64 * 93 * 2;  // the head's int16 voxels
  limits.admit_image = [&](const std::string& device, const ImageSize& size) {
    EXPECT_EQ(size.dims[0], 64);
    EXPECT_EQ(size.dims[1], 64);
    EXPECT_EQ(size.dims[2], 93);
    EXPECT_EQ(size.stored_bytes, 2u);
    held += body;
    devices.push_back(device);
    return AdmittedImage{"", std::shared_ptr<void>(nullptr, [&held, body](void*) { held -= body; }), body};
  };
  const engine::Volume file = io::load_volume(kHead);
  const std::vector<std::uint8_t> bytes = image_of(file, igtl::ImageMessage::ENDIAN_BIG);
  {
    MemorySource src(bytes);
    const Incoming in = read_message(src, limits);
    ASSERT_EQ(in.kind, Incoming::Kind::kImage) << in.why;
    EXPECT_EQ(held, body);
    EXPECT_EQ(in.held_bytes, body);
    ASSERT_EQ(devices.size(), 1u);
    EXPECT_EQ(devices[0], in.device);
  }
  EXPECT_EQ(held, 0u) << "the Incoming is gone: nothing held";
  {
    MemorySource src(std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + 58 + 72 + 1000));  // cut in its voxels
    const Incoming in = read_message(src, limits);
    EXPECT_EQ(in.kind, Incoming::Kind::kBroken);
    EXPECT_EQ(held, body) << "held while the cut IMAGE arrived, until its Incoming goes";
  }
  EXPECT_EQ(held, 0u);
  MemorySource src(transform_bytes("T", 1, 2, 3));
  EXPECT_EQ(read_message(src, limits).kind, Incoming::Kind::kTransform);
  EXPECT_EQ(devices.size(), 2u) << "a TRANSFORM is not held";
}

// An IMAGE admit_image refuses at its header is read and dropped (its voxels never held):
// refused as over the budget, nothing held, and the stream goes on with the next message.
TEST(ServiceMemory, AnImageRefusedAtItsHeaderIsDroppedAndTheStreamGoesOn) {
  MessageLimits limits;
  int asked = 0;
  limits.admit_image = [&](const std::string&, const ImageSize&) {
    ++asked;
    return AdmittedImage{"over the budget", nullptr, 0};
  };
  const engine::Volume file = io::load_volume(kHead);
  std::vector<std::uint8_t> all = image_of(file, igtl::ImageMessage::ENDIAN_BIG);
  const auto next = transform_bytes("T", 4, 5, 6);
  all.insert(all.end(), next.begin(), next.end());
  MemorySource src(all);
  const Incoming in = read_message(src, limits);
  EXPECT_EQ(in.kind, Incoming::Kind::kRefused);
  EXPECT_TRUE(in.over_budget);
  EXPECT_EQ(in.why, "over the budget");
  EXPECT_EQ(in.image, nullptr);
  EXPECT_EQ(in.held, nullptr);
  EXPECT_EQ(asked, 1);
  const Incoming after = read_message(src, limits);
  EXPECT_EQ(after.kind, Incoming::Kind::kTransform) << after.why;
  EXPECT_FALSE(after.over_budget);
}

TEST(ServiceMemory, WrongSizesAreRefusedFromTheHeaderAndTheStreamGoesOn) {
  std::vector<std::uint8_t> all = announced("TRANSFORM", 10, std::vector<std::uint8_t>(10, 7));
  const auto next = transform_bytes("T", 4, 5, 6);
  all.insert(all.end(), next.begin(), next.end());
  expect_refused_then_the_next(all, "TRANSFORM body is 10 bytes");
}

TEST(ServiceSocket, SlowDripIsDroppedAtTheMessageDeadline) {
  // One byte every 50 ms never trips the 300 ms silence timeout; the 600 ms message deadline ends it.
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  const std::vector<std::uint8_t> t = transform_bytes("T", 1, 2, 3);
  std::atomic<bool> done{false};
  std::thread drip([&] {
    for (std::size_t i = 0; i < t.size() && !done; ++i) {
      if (::write(sv[1], &t[i], 1) != 1) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  Connection c(sv[0], 300, 600, nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  Incoming in = read_message(c, MessageLimits{});
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  done = true;
  drip.join();
  ::close(sv[1]);
  EXPECT_EQ(in.kind, Incoming::Kind::kBroken);
  EXPECT_NE(in.why.find("not whole after 600 ms"), std::string::npos) << in.why;
  EXPECT_LT(s, 1.5);  // 166 bytes at 50 ms would take 8 s
}

TEST(ServiceSocket, DroppableSendToAPeerNotReadingNeverWaits) {
  // A TCP peer on loopback that never reads: its buffers fill, a send then fits only in part
  // (cut mid-message: the connection is dropped) or not at all (dropped); never waited for.
  Listener l("127.0.0.1", 0);
  const int peer = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(std::uint16_t(l.port()));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::connect(peer, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  const int fd = l.accept(1000);
  ASSERT_GE(fd, 0);
  Connection c(fd, 2000, 60000, nullptr);
  const std::vector<std::uint8_t> chunk(100000, 1);
  const auto t0 = std::chrono::steady_clock::now();
  int ok = 0, dropped = 0;
  for (int i = 0; i < 2000 && c.alive(); ++i) (c.send_droppable(chunk) ? ok : dropped) += 1;
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GT(dropped, 0) << ok << " sends all fitted: the buffer never filled";
  EXPECT_LT(s, 1.0) << ok << " sends, " << dropped << " dropped in " << s << " s (a send waited for the peer)";
  std::cout << ok << " sends fitted, " << dropped << " dropped, alive " << c.alive() << ", " << s << " s\n";
  ::close(peer);
}

// serve's reply to a pose while the display loop's send to the same client is under way: a
// send with a busy wait waits for it (and the peer gets both messages whole, in order) where
// one without drops at once. The other send holds the connection from its first byte in the
// peer's buffer until the peer reads, which it starts 50 ms after that.
TEST(ServiceSocket, ADroppableSendWaitsForAnotherSendUnderWayWithinItsBusyWait) {
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  int small = 4096;  // the smallest buffers: the large message fills them at once
  ::setsockopt(sv[0], SOL_SOCKET, SO_SNDBUF, &small, sizeof small);
  ::setsockopt(sv[1], SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
  Connection c(sv[0], 5000, 60000, nullptr);
  const std::vector<std::uint8_t> large(1 << 20, 7), reply(64, 9);
  std::thread other([&] {
    EXPECT_TRUE(c.send(large));  // blocks, holding the connection, until the peer reads
  });
  int queued = 0;  // the large message's first bytes at the peer: its send holds the connection
  for (int i = 0; i < 100000 && (::ioctl(sv[1], FIONREAD, &queued) != 0 || queued == 0); ++i)
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  ASSERT_GT(queued, 0) << "the other send never began";
  EXPECT_EQ(c.try_send(reply), Sent::kBusy) << "without a busy wait the reply is dropped at once";
  std::vector<std::uint8_t> got;
  std::thread peer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::uint8_t buf[65536];
    while (got.size() < large.size() + reply.size()) {
      const ssize_t k = ::read(sv[1], buf, sizeof buf);
      if (k <= 0) break;
      got.insert(got.end(), buf, buf + k);
    }
  });
  const auto t0 = std::chrono::steady_clock::now();
  const Sent sent = c.try_send(reply, 10'000'000'000);  // waits for the other send, however long it takes here
  const double waited_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  other.join();
  c.shutdown();  // the peer reads what was sent, then the end (a dropped reply: no hang)
  peer.join();
  // Waited for the other send: sent, or (the peer had not yet read the large message's last
  // bytes out of the small buffers) dropped as a full peer's, never as busy.
  ASSERT_TRUE(sent == Sent::kSent || sent == Sent::kFull) << "not sent after waiting " << waited_ms << " ms: " << int(sent);
  const std::size_t reply_bytes = sent == Sent::kSent ? reply.size() : 0;
  ASSERT_EQ(got.size(), large.size() + reply_bytes);
  EXPECT_TRUE(std::equal(large.begin(), large.end(), got.begin())) << "the large message is not whole";
  EXPECT_TRUE(std::equal(reply.begin(), reply.begin() + std::ptrdiff_t(reply_bytes), got.begin() + std::ptrdiff_t(large.size())))
      << "the reply is not whole, after it";
  ::close(sv[1]);
}

}  // namespace
}  // namespace isotouch::service

namespace isotouch::service {
namespace {

TEST(ServiceCommands, GrammarAndRefusalsNameTheCommandAndValue) {
  auto ok = [](const std::string& t) {
    auto r = parse_command(t);
    EXPECT_TRUE(std::holds_alternative<Command>(r)) << t << ": " << (std::holds_alternative<std::string>(r) ? std::get<std::string>(r) : "");
    return std::holds_alternative<Command>(r) ? std::get<Command>(r) : Command{};
  };
  EXPECT_EQ(ok("isovalue 500.5").value, 500.5);
  const Command t = ok("  tool smooth 3.5 0.4 ");
  EXPECT_EQ(t.tool, "smooth");
  EXPECT_EQ(t.radius_mm, 3.5);
  EXPECT_EQ(t.strength, 0.4);
  EXPECT_EQ(ok("tool drill").radius_mm, -1);
  EXPECT_EQ(ok("save out.nii.gz").file, "out.nii.gz");
  for (const char* bare : {"apply", "stop", "undo", "redo"}) EXPECT_EQ(to_string(ok(bare)), bare);
  const std::pair<const char*, const char*> bad[] = {
      {"isovalue", "isovalue: expected"},          {"isovalue 5x", "isovalue '5x': not a number"},
      {"isovalue nan", "isovalue 'nan': not finite"}, {"tool", "tool: expected"},
      {"tool saw 2", "tool kind 'saw'"},           {"tool carve -1", "tool radius '-1'"},
      {"tool smooth 2 1.5", "tool strength '1.5'"}, {"save /etc/x.mha", "save name '/etc/x.mha'"},
      {"save a b", "save: expected"},              {"undo 2", "undo: takes no value, got '2'"},
      {"", "empty command"},                       {"Isovalue 3", "unknown command 'Isovalue'"}};
  for (const auto& [text, why] : bad) {
    auto r = parse_command(text);
    ASSERT_TRUE(std::holds_alternative<std::string>(r)) << "'" << text << "' was taken";
    EXPECT_NE(std::get<std::string>(r).find(why), std::string::npos) << std::get<std::string>(r);
  }
}

TEST(ServiceImage, EditedVolumeGoesBackWhereItCameFrom) {
  // Whole: read back by the same path as any client's IMAGE, voxels and corners equal.
  const engine::Volume file = rotated_head();
  expect_same_place(file, received_volume(pack_image(file, "Head", VoxelBox{})));
  // A sub-volume: the library reads its offset and size, and exactly its voxels.
  VoxelBox box;
  box.lo = {3, 10, 20};
  box.hi = {11, 12, 29};
  MemorySource src(pack_image(file, "Head", box));
  Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kImage) << in.why;
  int size[3], off[3], dims[3];
  in.image->GetSubVolume(size, off);
  in.image->GetDimensions(dims);
  EXPECT_EQ(dims[0] * dims[1] * dims[2], 64 * 64 * 93);
  EXPECT_EQ(std::vector<int>(off, off + 3), (std::vector<int>{3, 10, 20}));
  EXPECT_EQ(std::vector<int>(size, size + 3), (std::vector<int>{8, 2, 9}));
  const auto* p = static_cast<const float*>(in.image->GetScalarPointer());
  std::size_t differ = 0;
  for (int z = 20; z < 29; ++z)
    for (int y = 10; y < 12; ++y)
      for (int x = 3; x < 11; ++x) differ += *p++ != file.voxels[std::size_t((z * 64 + y) * 64 + x)];
  EXPECT_EQ(differ, 0u);
}

TEST(ServiceImage, TheMirrorsChangedBoxCopiedIntoTheImageIsTheSubVolume) {
  // EditMirror: nothing changed, nothing to copy; a changed box once, then cleared; its voxels
  // copied straight into the IMAGE (a slice per lock) give the IMAGE pack_image gives.
  const engine::Volume file = rotated_head();
  const EditMirror mirror(file);
  EXPECT_TRUE(mirror.take_changed().empty());
  VoxelBox box;
  box.lo = {3, 10, 20};
  box.hi = {11, 12, 29};
  mirror.restore_changed(box);
  const VoxelBox got = mirror.take_changed();
  EXPECT_EQ(got.lo, box.lo);
  EXPECT_EQ(got.hi, box.hi);
  EXPECT_TRUE(mirror.take_changed().empty());
  engine::Volume frame = file;
  frame.voxels.clear();  // the frame alone: its voxels are not read
  const auto a = pack_image(frame, "Head", box, [&](float* out) { mirror.copy_box(box, out); });
  const auto b = pack_image(file, "Head", box);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_TRUE(std::equal(a.begin() + 58, a.end(), b.begin() + 58)) << "the bodies differ";  // headers: time stamps
}

TEST(ServiceMessages, LabelMetaNamesItsImages) {
  igtl::LabelMetaMessage::Pointer m = igtl::LabelMetaMessage::New();
  m->SetDeviceName("Labels");
  for (const char* image : {"Seg", "Organs"}) {
    igtl::LabelMetaElement::Pointer e = igtl::LabelMetaElement::New();
    e->SetName("label");
    e->SetDeviceName(image);
    m->AddLabelMetaElement(e);
  }
  std::vector<std::uint8_t> all = bytes_of(m);
  const auto next = transform_bytes("T", 4, 5, 6);
  all.insert(all.end(), next.begin(), next.end());
  MemorySource src(all);
  Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kLabelMeta) << in.why;
  EXPECT_EQ(in.labels, (std::vector<std::string>{"Seg", "Organs"}));
  EXPECT_EQ(read_message(src, MessageLimits{}).kind, Incoming::Kind::kTransform);
  // No labels at all (found by fuzz_igtl: an empty body copied from a null pointer): read
  // (or refused by its CRC), never a crash, and the stream goes on.
  std::vector<std::uint8_t> empty = announced("LBMETA", 0);
  empty.insert(empty.end(), next.begin(), next.end());
  MemorySource none(empty);
  Incoming e = read_message(none, MessageLimits{});
  EXPECT_TRUE(e.kind == Incoming::Kind::kLabelMeta || e.kind == Incoming::Kind::kRefused) << e.why;
  EXPECT_TRUE(e.labels.empty());
  EXPECT_EQ(read_message(none, MessageLimits{}).kind, Incoming::Kind::kTransform);
  // A body that is not whole labels: refused, the stream goes on.
  std::vector<std::uint8_t> odd = announced("LBMETA", 100, std::vector<std::uint8_t>(100, 0));
  odd.insert(odd.end(), next.begin(), next.end());
  expect_refused_then_the_next(odd, "LBMETA body of 100 bytes");
}


// The isovalue a received IMAGE opens at (issue 62: a new IMAGE kept the scene's isovalue in
// the scene volume's units). Truth from outside the chooser: three-layer volumes whose
// classes are known. A CT in HU (air -1024, tissue 40, bone 1200) opens at the bone preset,
// 300 HU; a client's isovalue inside its values is kept, one outside them is not; a uint8
// volume of 0 / 100 / 200 opens between its tissue and its dense class, also after a client
// set the head scene's 1150 (scanner units: outside its values).
engine::Volume three_layers(float air, float tissue, float dense) {
  engine::Volume v;
  v.grid.dims = {16, 16, 24};
  v.voxels.resize(v.grid.voxel_count());
  for (int z = 0; z < 24; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) v.voxels[v.grid.index(x, y, z)] = z < 8 ? air : z < 16 ? tissue : dense;
  v.update_stats();
  return v;
}

TEST(ServeIsovalue, AnImageOpensAtItsOwnIsovalueUnlessAClientSetOne) {
  const engine::Volume ct = three_layers(-1024.f, 40.f, 1200.f);
  engine::IsoChoice c = image_isovalue(ct, std::nullopt);
  EXPECT_EQ(c.iso.tau, 300.0) << c.rule;
  EXPECT_EQ(c.iso.inside, core::InsideIs::kAbove);
  // A client's value inside the image's values is kept; one outside it is not.
  c = image_isovalue(ct, core::Isosurface{800.0, core::InsideIs::kAbove});
  EXPECT_EQ(c.iso.tau, 800.0);
  EXPECT_NE(c.rule.find("client"), std::string::npos) << c.rule;
  c = image_isovalue(ct, core::Isosurface{5000.0, core::InsideIs::kAbove});
  EXPECT_EQ(c.iso.tau, 300.0) << c.rule;
  EXPECT_NE(c.rule.find("outside this image's values"), std::string::npos) << c.rule;

  const engine::Volume u8 = three_layers(0.f, 100.f, 200.f);
  c = image_isovalue(u8, std::nullopt);
  EXPECT_GT(c.iso.tau, 100.0) << c.rule;
  EXPECT_LE(c.iso.tau, 200.0) << c.rule;
  c = image_isovalue(u8, core::Isosurface{1150.0, core::InsideIs::kAbove});  // the head scene's, in other units
  EXPECT_GT(c.iso.tau, 100.0) << c.rule;
  EXPECT_LE(c.iso.tau, 200.0) << c.rule;
}

}  // namespace
}  // namespace isotouch::service
