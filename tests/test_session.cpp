// session::Session: the owned wiring of a live session (edit session, snapshots, renderer,
// live session) on an analytic sphere, CPU engine. Truth from outside the code: the sphere's
// radius and the renderer's stiffness give the force at a known depth (K d); a set-up that
// cannot be done is answered with its reason, not thrown.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>

#include <unistd.h>

#include "isotouch/engine/synthetic.h"
#include "isotouch/io/record.h"
#include "isotouch/session/session.h"

namespace fs = std::filesystem;
using isotouch::core::Vec3;
using isotouch::session::Session;

namespace {

constexpr double kSpacing = 1e-3, kRadiusVox = 12, kDepth = 1e-3, kStep = 2e-5, kK = 500;

isotouch::session::SessionOptions sphere_options() {
  isotouch::session::SessionOptions o;
  o.field = {{isotouch::engine::PassDesc::gradient()}, isotouch::core::Isosurface{0.0, isotouch::core::InsideIs::kAbove},
             -100.f, isotouch::core::SampleFormat::kFp32};
  o.hri.tau = 0;
  o.hri.stiffness_n_per_m = kK;
  o.hri.rate_hz = 1000;
  return o;
}

/// A hand that starts 2 mm above the sphere's top and moves down (-z) by kStep per reading
/// until it is kDepth inside, then holds still. Forces written are kept (the last one).
class Press final : public isotouch::servo::HapticDeviceIO {
 public:
  explicit Press(const Vec3& top) : top_(top) {}
  Vec3 read_position_m() override {
    const double travel = std::min(double(reads_.fetch_add(1)) * kStep, 2e-3 + kDepth);
    return top_ + Vec3{0, 0, 2e-3 - travel};
  }
  void write_force_n(const Vec3&) override {}
  long reads() const { return reads_.load(); }

 private:
  Vec3 top_;
  std::atomic<long> reads_{0};
};

isotouch::session::LiveSessionConfig polite() {
  isotouch::session::LiveSessionConfig c;
  c.servo.rate_hz = 1000;
  c.servo.sched_fifo = c.servo.pin_cpu = c.servo.lock_memory = false;
  return c;
}

}  // namespace

// Opened, attached and started with nothing else wired by the test: the hand pressed kDepth
// into the sphere feels K kDepth along +z (the sphere's normal at its top).
TEST(Session, OpenedOnASphereGivesKTimesDepth) {
  const isotouch::engine::Volume vol = isotouch::engine::make_sphere({40, 40, 40}, kSpacing, kRadiusVox);
  const Vec3 top = vol.grid.centre_m() + Vec3{0, 0, kRadiusVox * kSpacing};
  isotouch::session::Opened o = Session::open(isotouch::engine::Volume(vol), sphere_options());
  ASSERT_TRUE(o) << o.error;
  Press hand(top);
  ASSERT_TRUE(o.session->attach(hand, polite()));
  o.session->live()->start();
  const long held_from = long(std::ceil((2e-3 + kDepth) / kStep)) + 200;  // readings: at depth, then settled
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (hand.reads() < held_from && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const isotouch::session::Observed seen = o.session->live()->observe();
  o.session->live()->stop();
  ASSERT_GE(hand.reads(), held_from) << "the servo did not run";
  EXPECT_TRUE(seen.contact);
  EXPECT_NEAR(seen.force_n.z, kK * kDepth, 0.03 * kK * kDepth);
  EXPECT_NEAR(seen.force_n.x, 0.0, 0.01 * kK * kDepth);
  EXPECT_NEAR(seen.force_n.y, 0.0, 0.01 * kK * kDepth);
}

// What cannot be built is answered with its reason (and the exception behind it), never
// thrown: a volume the engine refuses, a live session whose recording cannot be created.
TEST(Session, ASetUpThatFailsIsReported) {
  isotouch::session::Opened bad;
  EXPECT_NO_THROW(bad = Session::open(isotouch::engine::Volume{}, sphere_options()));
  EXPECT_FALSE(bad);
  EXPECT_EQ(bad.session, nullptr);
  EXPECT_NE(bad.error.find("building the edit session"), std::string::npos) << bad.error;
  EXPECT_TRUE(bad.cause);

  // A renderer told another isovalue than the field's would feel a surface whose bricks are
  // not the active ones: refused, naming both.
  isotouch::session::SessionOptions other = sphere_options();
  other.hri.tau = 0.5;
  isotouch::session::Opened mismatch =
      Session::open(isotouch::engine::make_sphere({40, 40, 40}, kSpacing, kRadiusVox), other);
  EXPECT_FALSE(mismatch);
  EXPECT_NE(mismatch.error.find("hri.tau 0.5"), std::string::npos) << mismatch.error;
  EXPECT_NE(mismatch.error.find("field.iso.tau 0"), std::string::npos) << mismatch.error;

  isotouch::session::Opened o =
      Session::open(isotouch::engine::make_sphere({40, 40, 40}, kSpacing, kRadiusVox), sphere_options());
  ASSERT_TRUE(o) << o.error;
  Press hand({});
  isotouch::session::LiveSessionConfig c = polite();
  const fs::path missing = fs::temp_directory_path() / ("isotouch-no-such-" + std::to_string(::getpid())) / "s.rec";
  c.record_path = missing.string();
  isotouch::session::SetupResult r;
  EXPECT_NO_THROW(r = o.session->attach(hand, c));
  EXPECT_FALSE(r);
  EXPECT_NE(r.error.find("s.rec"), std::string::npos) << r.error;
  EXPECT_THROW(std::rethrow_exception(r.cause), isotouch::io::RecordingError);
  EXPECT_EQ(o.session->live(), nullptr);
  // The same session still attaches a good config afterwards.
  EXPECT_TRUE(o.session->attach(hand, polite()));
  EXPECT_NE(o.session->live(), nullptr);
}
