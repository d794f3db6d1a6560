// Recordings (io/record.h): the JSON-lines format round-trips every
// double bit for bit (random bit patterns incl. subnormals, -0.0, huge), the save is atomic
// (a write that fails - the file size limit in a child process - leaves the old file
// whole), bad files are refused with the file, the line, the field and the value named,
// and garbage (random bytes, truncations and byte flips of a good file) never crashes the
// loader: it returns a recording or throws RecordingError, nothing else.
#include <gtest/gtest.h>

#include <algorithm>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <bit>
#include <csignal>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "isotouch/io/record.h"

namespace fs = std::filesystem;
using isotouch::session::EditEvent;
using isotouch::io::load_recording;
using isotouch::io::parse_recording;
using isotouch::io::RecordedTick;
using isotouch::io::Recording;
using isotouch::io::recording_text;
using isotouch::io::RecordingError;
using isotouch::io::save_recording;
using isotouch::core::Vec3;
using isotouch::session::BrushKind;

namespace {

fs::path temp_dir(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() / ("isotouch_test_record_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A finite double from random bits, with the awkward ones mixed in: subnormals, -0.0,
/// the largest and smallest normals, and values with 17 significant digits.
double awkward(std::mt19937_64& rng) {
  static const double special[] = {0.0,
                                   -0.0,
                                   std::numeric_limits<double>::denorm_min(),
                                   -std::numeric_limits<double>::denorm_min(),
                                   std::numeric_limits<double>::min(),
                                   std::nextafter(std::numeric_limits<double>::min(), 0.0),
                                   std::numeric_limits<double>::max(),
                                   -std::numeric_limits<double>::max(),
                                   0.1,
                                   1.0 / 3.0,
                                   1e-300,
                                   123456789012345678.0};
  const std::uint64_t pick = rng() % 4;
  if (pick == 0) return special[rng() % std::size(special)];
  if (pick == 1) {  // subnormal: exponent bits 0
    return std::bit_cast<double>(rng() & 0x800FFFFFFFFFFFFFull);
  }
  for (;;) {  // any finite bit pattern
    const double d = std::bit_cast<double>(rng());
    if (std::isfinite(d)) return d;
  }
}
Vec3 awkward3(std::mt19937_64& rng) { return {awkward(rng), awkward(rng), awkward(rng)}; }

/// A float from random bits (finite).
float awkward_float(std::mt19937_64& rng) {
  for (;;) {
    const float f = std::bit_cast<float>(std::uint32_t(rng()));
    if (std::isfinite(f)) return f;
  }
}

/// A recording with random ticks and edits: every number awkward (the format does not
/// check brushes for sense on save; validity is checked on load only for brush events, so
/// those get valid values mixed with awkward bits where validate() allows them).
Recording random_recording(std::mt19937_64& rng, std::size_t ticks, std::size_t edits) {
  Recording r;
  r.scene_path = "/tmp/scene \"quoted\" \\ ünïcode.json";
  r.scene_text = "{\n  \"name\": \"x\",\n\t\"a\": [1, 2]\n}\n\x01\x7f";
  r.rate_hz = 1000.0 + std::ldexp(double(rng() % 1000), -40);
  r.volume_crc32 = std::uint32_t(rng());
  double t = awkward(rng);
  if (std::abs(t) > 1e300) t = -1e300;
  for (std::size_t k = 0; k < ticks; ++k) {
    RecordedTick tk;
    tk.t_s = t;
    t = std::nextafter(t, std::numeric_limits<double>::infinity()) + (rng() % 2 ? 1e-3 : 0.0);
    tk.hip_m = awkward3(rng);
    tk.force_n = awkward3(rng);
    tk.vhip_m = awkward3(rng);
    tk.version = 1 + rng() % (1ull << 62);
    tk.fault = rng() % 7 == 0;
    tk.button = rng() % 2;
    r.ticks.push_back(tk);
  }
  long tick = 0;
  for (std::size_t i = 0; i < edits; ++i) {
    tick = std::min<long>(long(ticks) - 1, tick + long(rng() % 3));
    EditEvent e;
    e.kind = EditEvent::Kind(rng() % 5);
    e.tick = tick;
    e.t_s = awkward(rng);
    auto& b = e.brush;
    b.kind = BrushKind(rng() % 4);
    b.centre_m = awkward3(rng);
    b.radius_m = std::ldexp(double(1 + rng() % 1000), -int(10 + rng() % 20));  // (0, 10]
    b.strength = b.kind == BrushKind::kSmooth ? double(rng() % 1000) / 999.0
                                              : std::ldexp(double(rng() % 100000), -int(rng() % 30));
    b.falloff = 1.0 - std::ldexp(double(rng() % 1000), -12);
    b.targets.material = awkward_float(rng);
    b.targets.empty = awkward_float(rng);
    b.targets.density_scale = std::abs(awkward_float(rng)) + 1e-30f;
    b.force_n = std::abs(awkward(rng)) * 1e-300;  // small, >= 0
    b.force_threshold_n = std::abs(awkward(rng)) * 1e-300;
    b.rate = std::ldexp(double(rng() % 100000), -int(rng() % 20));
    b.dt_s = std::ldexp(1.0, -10);
    r.edits.push_back(e);
  }
  return r;
}

bool same_bits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }
bool same_bits(const Vec3& a, const Vec3& b) { return same_bits(a.x, b.x) && same_bits(a.y, b.y) && same_bits(a.z, b.z); }

/// Field-by-field, bit for bit; the first difference in `why`.
bool identical(const Recording& a, const Recording& b, std::string& why) {
  if (a.format_version != b.format_version) return why = "format_version", false;
  if (a.scene_path != b.scene_path) return why = "scene_path", false;
  if (a.scene_text != b.scene_text) return why = "scene_text", false;
  if (!same_bits(a.rate_hz, b.rate_hz)) return why = "rate_hz", false;
  if (a.volume_crc32 != b.volume_crc32) return why = "volume_crc32", false;
  if (a.ticks.size() != b.ticks.size()) return why = "tick count", false;
  if (a.edits.size() != b.edits.size()) return why = "edit count", false;
  for (std::size_t k = 0; k < a.ticks.size(); ++k) {
    const auto &x = a.ticks[k], &y = b.ticks[k];
    if (!same_bits(x.t_s, y.t_s) || !same_bits(x.hip_m, y.hip_m) || !same_bits(x.force_n, y.force_n) ||
        x.button != y.button || !same_bits(x.vhip_m, y.vhip_m) || x.version != y.version || x.fault != y.fault ||
        !same_bits(x.dt_s, y.dt_s) || x.held != y.held || x.reset != y.reset ||
        x.passivity_clock_s.has_value() != y.passivity_clock_s.has_value() ||
        (x.passivity_clock_s && (!same_bits(*x.passivity_clock_s, *y.passivity_clock_s) || !same_bits(x.sent_n, y.sent_n))))
      return why = "tick " + std::to_string(k), false;
  }
  for (std::size_t i = 0; i < a.edits.size(); ++i) {
    const auto &x = a.edits[i], &y = b.edits[i];
    const auto &p = x.brush, &q = y.brush;
    const bool same = x.kind == y.kind && x.tick == y.tick && same_bits(x.t_s, y.t_s) && p.kind == q.kind &&
                      same_bits(p.centre_m, q.centre_m) && same_bits(p.radius_m, q.radius_m) &&
                      same_bits(p.strength, q.strength) && same_bits(p.falloff, q.falloff) &&
                      std::bit_cast<std::uint32_t>(p.targets.material) == std::bit_cast<std::uint32_t>(q.targets.material) &&
                      std::bit_cast<std::uint32_t>(p.targets.empty) == std::bit_cast<std::uint32_t>(q.targets.empty) &&
                      std::bit_cast<std::uint32_t>(p.targets.density_scale) ==
                          std::bit_cast<std::uint32_t>(q.targets.density_scale) &&
                      same_bits(p.force_n, q.force_n) && same_bits(p.force_threshold_n, q.force_threshold_n) &&
                      same_bits(p.rate, q.rate) && same_bits(p.dt_s, q.dt_s);
    if (!same) return why = "edit " + std::to_string(i), false;
  }
  return true;
}

/// A small valid recording's text: 3 ticks, a brush after tick 1.
std::string small_text() {
  Recording r;
  r.scene_path = "/abs/scene.json";
  r.scene_text = "{}";
  r.rate_hz = 1000;
  r.volume_crc32 = 123456789u;
  for (int k = 0; k < 3; ++k)
    r.ticks.push_back({k * 1e-3, {0.01, 0.02, 0.03}, k == 1, {0, 0, 0.5 * k}, {0.01, 0.02, 0.025}, std::uint64_t(k + 1)});
  EditEvent e;
  e.kind = EditEvent::Kind::kBrush;
  e.tick = 1;
  e.t_s = 1e-3;
  e.brush.kind = BrushKind::kCarve;
  e.brush.centre_m = {0.01, 0.02, 0.03};
  r.edits.push_back(e);
  return recording_text(r, "small");
}

/// Replaces the first `from` in `s` (must be there).
std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

/// The RecordingError message of parsing `text` ("" if it parsed).
std::string error_of(const std::string& text) {
  try {
    (void)parse_recording(text, "bad.rec");
  } catch (const RecordingError& e) {
    return e.what();
  }
  return "";
}

/// `text` with its first `from` made `to` must be refused, the message holding `says`.
void expect_refused(const std::string& text, const std::string& from, const std::string& to, const std::string& says) {
  SCOPED_TRACE(to);
  const std::string why = error_of(replaced(text, from, to));
  EXPECT_NE(why, "") << "accepted " << to;
  EXPECT_NE(why.find(says), std::string::npos) << why;
}

}  // namespace

TEST(Record, RandomRecordingsRoundTripBitForBit) {
  std::mt19937_64 rng(20261121);
  for (int trial = 0; trial < 20; ++trial) {
    const Recording r = random_recording(rng, 1 + rng() % 300, rng() % 40);
    const std::string text = recording_text(r, "mem");
    const Recording back = parse_recording(text, "mem");
    std::string why;
    EXPECT_TRUE(identical(r, back, why)) << "trial " << trial << ": " << why;
    EXPECT_EQ(recording_text(back, "mem"), text) << "trial " << trial;  // a fixed point
  }
}

/// A live session's recording (format 3): measured dt per tick, edits with the tick count
/// when they were applied (ascending, possibly past the last tick line).
Recording live_recording(std::mt19937_64& rng, std::size_t ticks, std::size_t edits) {
  Recording r = random_recording(rng, ticks, edits);
  r.format_version = 3;
  for (std::size_t k = 0; k < r.ticks.size(); ++k) {
    r.ticks[k].dt_s = k == 0 ? 0.0 : std::ldexp(double(1 + rng() % 100000), -int(17 + rng() % 10));
    // Held ticks (paused, device not ok) and the reset after them.
    const unsigned h = unsigned(rng() % 9);
    r.ticks[k].held = h == 0;
    r.ticks[k].reset = h == 1;
    // The passivity stage's clock and the force sent, on the ticks it stepped.
    if (!r.ticks[k].held && h % 2 == 0) {
      r.ticks[k].passivity_clock_s = std::ldexp(double(rng() % 1000000), -20);
      r.ticks[k].sent_n = {std::ldexp(double(rng() % 4096), -10), -0.0, 1.0 / 3.0};
    }
  }
  if (!r.edits.empty()) r.edits.back().tick = long(ticks);  // applied after the last tick ran
  return r;
}

TEST(Record, LiveRecordingsRoundTripBitForBit) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 10; ++trial) {
    const Recording r = live_recording(rng, 1 + rng() % 300, 1 + rng() % 40);
    const std::string text = recording_text(r, "mem");
    const Recording back = parse_recording(text, "mem");
    std::string why;
    EXPECT_TRUE(identical(r, back, why)) << "trial " << trial << ": " << why;
    EXPECT_TRUE(back.complete);
    EXPECT_NE(text.find("\"dt\":"), std::string::npos);
    const bool any_held = std::any_of(r.ticks.begin(), r.ticks.end(), [](const RecordedTick& t) { return t.held; });
    const bool any_reset = std::any_of(r.ticks.begin(), r.ticks.end(), [](const RecordedTick& t) { return t.reset; });
    EXPECT_EQ(text.find("\"held\":true") != std::string::npos, any_held);
    EXPECT_EQ(text.find("\"reset\":true") != std::string::npos, any_reset);
  }
}

TEST(Record, ACutLiveRecordingLoadsUpToItsLastWholeLine) {
  std::mt19937_64 rng(4);
  const Recording r = live_recording(rng, 50, 5);
  const std::string text = recording_text(r, "mem");
  // Cut in the middle of tick 30's line (after a SIGKILL the last chunk may end anywhere).
  const std::size_t at = text.find("{\"k\":30,");
  ASSERT_NE(at, std::string::npos);
  const std::string cut = text.substr(0, at + 20);
  EXPECT_THROW((void)parse_recording(cut, "cut"), RecordingError);  // refused unless allowed
  const Recording back = parse_recording(cut, "cut", /*allow_incomplete=*/true);
  EXPECT_FALSE(back.complete);
  ASSERT_EQ(back.ticks.size(), 30u);
  for (std::size_t k = 0; k < 30; ++k) {
    EXPECT_TRUE(same_bits(back.ticks[k].dt_s, r.ticks[k].dt_s)) << k;
    EXPECT_TRUE(same_bits(back.ticks[k].force_n, r.ticks[k].force_n)) << k;
  }
  // Cut at a line end: the same, with no partial line to drop.
  const Recording whole_lines = parse_recording(text.substr(0, at), "cut", true);
  EXPECT_EQ(whole_lines.ticks.size(), 30u);
  // A format 2 recording (written whole, after the run, by earlier versions of `isotouch run`) is never accepted cut.
  std::mt19937_64 rng2(5);
  const std::string two = recording_text(random_recording(rng2, 50, 0), "mem");
  EXPECT_THROW((void)parse_recording(two.substr(0, two.size() / 2), "cut", true), RecordingError);
}

TEST(Record, LiveRecordingsRefuseBadDtAndEditsOutOfOrder) {
  std::mt19937_64 rng(6);
  Recording r = live_recording(rng, 10, 3);
  const std::string text = recording_text(r, "mem");
  const std::string dt1 = "\"dt\":";
  const std::size_t at = text.find(dt1, text.find("{\"k\":2,"));
  ASSERT_NE(at, std::string::npos);
  const std::size_t end = text.find(',', at);
  std::string neg = text;
  neg.replace(at + dt1.size(), end - at - dt1.size(), "-0.001");
  try {
    (void)parse_recording(neg, "neg.rec");
    ADD_FAILURE() << "a negative dt was accepted";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("field 'dt': must be in [0, 3600) s, got -0.001"), std::string::npos) << e.what();
  }
  r.edits[2].tick = r.edits[1].tick - 1;
  EXPECT_THROW((void)recording_text(r, "mem"), RecordingError);
}

// The passivity stage's clock and sent force: both or neither, format 3, finite; old files
// (without them) load with neither.
TEST(Record, PassivityClockAndSentForceComeTogetherAndAreNamedWhenBad) {
  std::mt19937_64 rng(11);
  Recording r = live_recording(rng, 10, 0);
  for (auto& t : r.ticks) t.held = t.reset = false, t.passivity_clock_s.reset();
  const std::string text = recording_text(r, "mem");
  EXPECT_EQ(text.find("\"pt\""), std::string::npos);
  for (const auto& t : parse_recording(text, "mem").ticks) EXPECT_FALSE(t.passivity_clock_s);
  const std::string tick3 = "{\"k\":3,";
  const std::size_t at = text.find(tick3);
  ASSERT_NE(at, std::string::npos);
  auto with = [&](const std::string& fields) {
    std::string t = text;
    t.insert(at + tick3.size(), fields);
    return t;
  };
  const Recording ok = parse_recording(with("\"pt\":0.25,\"sent\":[0,0,1.5],"), "mem");
  ASSERT_TRUE(ok.ticks[3].passivity_clock_s);
  EXPECT_EQ(*ok.ticks[3].passivity_clock_s, 0.25);
  EXPECT_EQ(ok.ticks[3].sent_n.z, 1.5);
  const std::pair<std::string, std::string> bad[] = {
      {"\"pt\":0.25,", "line 5 (tick 3): field 'sent': missing"},
      {"\"sent\":[0,0,1],", "line 5 (tick 3): field 'pt': missing"},
      {"\"pt\":-1,\"sent\":[0,0,1],", "field 'pt': must be in [0, 1e9) s, got -1"},
      {"\"pt\":1,\"sent\":[0,\"x\",1],", "field 'sent[1]': must be a finite number"},
      // A held tick sent its zero without the stage: it has no stage clock.
      {"\"held\":true,\"pt\":0.5,\"sent\":[0,0,0],", "mem: line 5 (tick 3): field 'pt': a held tick has no passivity stage, got 0.5 s"},
  };
  for (const auto& [fields, expect] : bad) {
    try {
      (void)parse_recording(with(fields), "mem");
      ADD_FAILURE() << fields << " accepted";
    } catch (const RecordingError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  Recording two = r;
  two.format_version = 2;
  two.ticks[3].passivity_clock_s = 1.0;
  EXPECT_THROW((void)recording_text(two, "mem"), RecordingError);
  r.ticks[3].passivity_clock_s = 1.0;
  r.ticks[3].sent_n = {0, NAN, 0};
  EXPECT_THROW((void)recording_text(r, "mem"), RecordingError);
  r.ticks[3].sent_n = {};
  r.ticks[3].held = true;  // the writer refuses what the reader would
  EXPECT_THROW((void)recording_text(r, "mem"), RecordingError);
}

TEST(Record, HeldAndResetFlagsAreFormatThreesAndWrittenOnlyWhenTrue) {
  std::mt19937_64 rng(7);
  Recording r = live_recording(rng, 10, 0);
  for (auto& t : r.ticks) t.held = t.reset = false, t.passivity_clock_s.reset();
  const std::string text = recording_text(r, "mem");
  const std::string tick3 = "{\"k\":3,";
  const std::size_t at = text.find(tick3);
  ASSERT_NE(at, std::string::npos);
  auto with = [&](const std::string& flags) {
    std::string t = text;
    t.insert(at + tick3.size(), flags);
    return t;
  };
  const Recording held = parse_recording(with("\"held\":true,"), "mem");
  EXPECT_TRUE(held.ticks[3].held);
  EXPECT_FALSE(held.ticks[2].held || held.ticks[4].held || held.ticks[3].reset);
  EXPECT_TRUE(parse_recording(with("\"reset\":true,"), "mem").ticks[3].reset);
  const std::pair<std::string, std::string> bad[] = {
      {"\"held\":false,", "line 5 (tick 3): field 'held': written only when true"},
      {"\"reset\":1,", "line 5 (tick 3): field 'reset'"},
      {"\"held\":true,\"reset\":true,", "field 'reset': a held tick is not rendered"},
  };
  for (const auto& [flags, expect] : bad) {
    try {
      (void)parse_recording(with(flags), "mem");
      ADD_FAILURE() << flags << " accepted";
    } catch (const RecordingError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  // Format 2 has no such field: refused on reading and on writing.
  Recording two = r;
  two.format_version = 2;
  std::string t2 = recording_text(two, "mem");
  t2.insert(t2.find(tick3) + tick3.size(), "\"held\":true,");
  EXPECT_THROW((void)parse_recording(t2, "mem"), RecordingError);
  two.ticks[3].reset = true;
  EXPECT_THROW((void)recording_text(two, "mem"), RecordingError);
}

TEST(Record, SaveLoadThroughTheFileIsExact) {
  const fs::path dir = temp_dir("file");
  std::mt19937_64 rng(7);
  const Recording r = random_recording(rng, 2000, 50);
  save_recording((dir / "a.rec").string(), r);
  const Recording back = load_recording((dir / "a.rec").string());
  std::string why;
  EXPECT_TRUE(identical(r, back, why)) << why;
  // Nothing but the file is left in the folder (no temp files).
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
  fs::remove_all(dir);
}

TEST(Record, SpecialDoublesSurviveOneByOne) {
  // Each one alone as a HIP coordinate, checked against the bits (not the == of doubles,
  // which would call -0.0 and 0.0 the same).
  const double v[] = {-0.0, 0.0, std::numeric_limits<double>::denorm_min(), 4.9406564584124654e-324 * 3,
                      2.2250738585072009e-308, std::numeric_limits<double>::max(), 1e23, 9007199254740993.0,
                      0.30000000000000004, -1.7976931348623157e308};
  for (double d : v) {
    Recording r;
    r.rate_hz = 1000;
    r.volume_crc32 = 0;
    r.ticks.push_back({0, {d, -d, d * 0.5}, false, {d, d, d}, {d, d, -d}, 1});
    const Recording back = parse_recording(recording_text(r, "m"), "m");
    EXPECT_TRUE(same_bits(back.ticks[0].hip_m, r.ticks[0].hip_m)) << d;
    EXPECT_TRUE(same_bits(back.ticks[0].force_n, r.ticks[0].force_n)) << d;
    EXPECT_TRUE(same_bits(back.ticks[0].vhip_m, r.ticks[0].vhip_m)) << d;
  }
}

TEST(Record, FormatOneRecordingsStillLoad) {
  // A format 1 file (no volume checksum, VHIP or version): read, and written back as format 1.
  Recording r;
  r.format_version = 1;
  r.scene_path = "/abs/scene.json";
  r.rate_hz = 1000;
  r.ticks.push_back({0, {0.01, 0.02, 0.03}, false, {0, 0, 0.5}});
  const std::string text = recording_text(r, "v1");
  EXPECT_EQ(text.find("vhip"), std::string::npos);
  EXPECT_EQ(text.find("volume_crc32"), std::string::npos);
  const Recording back = parse_recording(text, "v1");
  EXPECT_EQ(back.format_version, 1);
  EXPECT_FALSE(back.volume_crc32.has_value());
  EXPECT_EQ(back.ticks[0].version, 0u);
  EXPECT_EQ(recording_text(back, "v1"), text);
}

TEST(Record, AFailedSaveLeavesTheOldFileWhole) {
  const fs::path dir = temp_dir("atomic");
  const std::string path = (dir / "run.rec").string();
  std::mt19937_64 rng(3);
  const Recording old_r = random_recording(rng, 50, 5);
  save_recording(path, old_r);
  const std::string old_bytes = read(path);
  const Recording big = random_recording(rng, 20000, 100);  // ~ MB: over the child's file size limit

  // A child saves with a file size limit of 64 kB: write() fails with EFBIG mid-file (the
  // signal SIGXFSZ ignored). The child exits 0 when save_recording threw RecordingError.
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::signal(SIGXFSZ, SIG_IGN);
    rlimit lim{65536, 65536};
    ::setrlimit(RLIMIT_FSIZE, &lim);
    try {
      save_recording(path, big);
    } catch (const RecordingError& e) {
      const bool named = std::string(e.what()).find(path) != std::string::npos;
      ::_exit(named ? 0 : 3);
    } catch (...) {
      ::_exit(4);
    }
    ::_exit(5);  // saved: the limit did not bite
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "3: message without the path, 4: other exception, 5: saved anyway";
  EXPECT_EQ(read(path), old_bytes);  // the old file, whole
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1) << "a temp file was left";

  // And a recording that cannot be written faithfully (a NaN HIP) is refused before the
  // file is touched, naming the tick and the field.
  Recording nan_r = old_r;
  nan_r.ticks[7].hip_m.y = std::nan("");
  try {
    save_recording(path, nan_r);
    ADD_FAILURE() << "a NaN HIP was saved";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("tick 7: field 'hip'"), std::string::npos) << e.what();
  }
  EXPECT_EQ(read(path), old_bytes);
  fs::remove_all(dir);
}

TEST(Record, BadFilesNameTheLineTheFieldAndTheValue) {
  const std::string good = small_text();
  ASSERT_EQ(error_of(good), "");
  // Lines: 1 header, 2 tick 0, 3 tick 1, 4 edit 0, 5 tick 2, 6 end.
  struct Case {
    std::string what, text;
    std::vector<std::string> expect;  // substrings of the message
  };
  const std::string no_end = good.substr(0, good.rfind("{\"end\""));
  const std::vector<Case> cases = {
      {"truncated: no end record", no_end, {"bad.rec: truncated after line 5", "3 ticks, 1 edits read", "no end record"}},
      {"truncated mid-line", good.substr(0, good.size() / 2), {"bad.rec: line ", "truncated"}},
      {"empty", "", {"bad.rec: empty"}},
      {"wrong type", replaced(good, "\"button\":true", "\"button\":\"yes\""),
       {"bad.rec: line 3 (tick 1): field 'button'", "true or false", "\"yes\""}},
      {"NaN HIP as null", replaced(good, "\"hip\":[0.01,0.02,0.03]", "\"hip\":[0.01,null,0.03]"),
       {"bad.rec: line 2 (tick 0): field 'hip[1]'", "finite number", "null"}},
      {"NaN HIP as NaN", replaced(good, "\"hip\":[0.01,0.02,0.03]", "\"hip\":[0.01,NaN,0.03]"),
       {"bad.rec: line 2: not valid JSON"}},
      {"infinite HIP", replaced(good, "\"hip\":[0.01,0.02,0.03]", "\"hip\":[0.01,1e999,0.03]"),
       {"bad.rec: line 2: not valid JSON", "1e999"}},
      {"HIP of 2", replaced(good, "\"hip\":[0.01,0.02,0.03]", "\"hip\":[0.01,0.02]"),
       {"line 2 (tick 0): field 'hip'", "array of 3", "[0.01,0.02]"}},
      {"ticks not ascending", replaced(good, "\"t\":0.002", "\"t\":0.001"),
       {"bad.rec: line 5 (tick 2): field 't'", "0.001 s is not after the previous tick's 0.001 s"}},
      {"tick skipped", replaced(good, "{\"k\":2", "{\"k\":3"), {"line 5 (tick 2): field 'k'", "expected tick 2, got 3"}},
      {"unknown brush kind", replaced(good, "\"kind\":\"carve\"", "\"kind\":\"chisel\""),
       {"bad.rec: line 4 (edit 0): field 'brush.kind'", "unknown brush kind \"chisel\""}},
      {"unknown edit kind", replaced(good, "\"edit\":\"brush\"", "\"edit\":\"paint\""),
       {"line 4 (edit 0): field 'edit'", "\"paint\""}},
      {"invalid brush", replaced(good, "\"radius_m\":0.002", "\"radius_m\":-0.002"),
       {"line 4 (edit 0): field 'brush'", "radius_m", "-0.002"}},
      {"target not a float", replaced(good, "\"empty\":0.0", "\"empty\":0.1"),
       {"line 4 (edit 0): field 'brush.targets.empty'", "float value", "0.1"}},
      {"edit of another tick", replaced(good, "\"tick\":1", "\"tick\":0"),
       {"line 4 (edit 0): field 'tick'", "0 is not the tick just before it (1)"}},
      {"unknown field", replaced(good, "\"button\":true", "\"button\":true,\"buton\":1"),
       {"line 3 (tick 1): field 'buton'", "unknown field"}},
      {"format version", replaced(good, "\"format_version\":2", "\"format_version\":4"),
       {"line 1 (header): field 'format_version'", "4 is not supported"}},
      {"no volume checksum", replaced(good, ",\"volume_crc32\":123456789", ""),
       {"line 1 (header): field 'volume_crc32'"}},
      {"checksum out of range", replaced(good, "\"volume_crc32\":123456789", "\"volume_crc32\":4294967296"),
       {"line 1 (header): field 'volume_crc32'", "4294967296"}},
      {"no VHIP", replaced(good, ",\"vhip\":[0.01,0.02,0.025]", ""), {"line 2 (tick 0): field 'vhip'"}},
      {"fault false", replaced(good, "\"version\":1", "\"version\":1,\"fault\":false"),
       {"line 2 (tick 0): field 'fault'", "only when true"}},
      {"snapshot version 0", replaced(good, "\"version\":1", "\"version\":0"),
       {"line 2 (tick 0): field 'version'", "got 0"}},
      {"format 1 with a VHIP", replaced(good, "\"format_version\":2", "\"format_version\":1"),
       {"line 1 (header): field 'volume_crc32'", "unknown field"}},
      {"not a recording", replaced(good, "isotouch-recording", "isotouch-scene"),
       {"line 1 (header): field 'format'", "\"isotouch-scene\""}},
      {"end count", replaced(good, "\"ticks\":3", "\"ticks\":4"), {"line 6 (end): field 'ticks'", "says 4, the file has 3"}},
      {"after the end", good + "{\"k\":3}\n", {"line 7: text after the end record"}},
      {"rate", replaced(good, "\"rate_hz\":1000.0", "\"rate_hz\":-5"), {"line 1 (header): field 'rate_hz'", "-5"}},
      {"negative tick", replaced(good, "{\"k\":0", "{\"k\":-1"), {"line 2 (tick 0): field 'k'", "got -1"}},
      {"not an object", replaced(good, "{\"k\":0,", "[0,{\"k\":0,") + "", {"line 2"}},
  };
  for (const Case& c : cases) {
    const std::string msg = error_of(c.text);
    EXPECT_FALSE(msg.empty()) << c.what << ": accepted";
    for (const std::string& s : c.expect) EXPECT_NE(msg.find(s), std::string::npos) << c.what << ": \"" << s << "\" not in: " << msg;
  }
}

// The sculpting app's edit session travels in a format 3 header: written, read back, checked.
TEST(Record, EditSessionRoundTripsAndBadOnesAreNamed) {
  std::mt19937_64 rng(8);
  Recording r = live_recording(rng, 20, 3);
  r.edit_session = isotouch::io::RecordedEditSession{true, 64.5, 0.007};
  const std::string text = recording_text(r, "mem");
  EXPECT_NE(text.find("\"edit_session\":{\"gpu_brushes\":true,\"history_limit_mib\":64.5,\"edit_period_s\":0.007}"), std::string::npos)
      << text.substr(0, 300);
  const Recording back = parse_recording(text, "mem");
  ASSERT_TRUE(back.edit_session.has_value());
  EXPECT_TRUE(back.edit_session->gpu_brushes);
  EXPECT_EQ(back.edit_session->history_limit_mib, 64.5);
  EXPECT_EQ(back.edit_session->edit_period_s, 0.007);
  EXPECT_EQ(recording_text(back, "mem"), text);
  expect_refused(text, "\"history_limit_mib\":64.5", "\"history_limit_mib\":-1",
          "bad.rec: line 1 (header): field 'edit_session.history_limit_mib': must be > 0, got -1");
  expect_refused(text, "\"gpu_brushes\":true", "\"gpu_brushes\":1", "field 'edit_session.gpu_brushes': must be true or false, got 1");
  expect_refused(text, "\"gpu_brushes\":true", "\"gpu_brushes\":true,\"brush\":2", "field 'edit_session.brush': unknown field");
  expect_refused(text, "\"format_version\":3", "\"format_version\":2", "field 'edit_session': unknown field");
  // A writer never puts one in a format 2 file.
  Recording two = random_recording(rng, 5, 0);
  two.edit_session = isotouch::io::RecordedEditSession{};
  EXPECT_THROW((void)recording_text(two, "mem"), RecordingError);
}

// serve's edit journal: the isovalue its session ran at and where its undo history restarted
// (an `isovalue V` rebuilt it) travel in the format 3 header: written, read back, checked.
TEST(Record, AJournalsIsovalueAndHistoryRestartsRoundTripAndBadOnesAreNamed) {
  std::mt19937_64 rng(9);
  Recording r = live_recording(rng, 20, 3);
  r.isovalue = isotouch::core::Isosurface{-500.25, isotouch::core::InsideIs::kBelow};
  r.history_restarts = {2, 2, 7};
  const std::string text = recording_text(r, "mem");
  EXPECT_NE(text.find("\"isovalue\":{\"tau\":-500.25,\"inside\":\"below\"}"), std::string::npos) << text.substr(0, 300);
  EXPECT_NE(text.find("\"history_restarts\":[2,2,7]"), std::string::npos) << text.substr(0, 300);
  const Recording back = parse_recording(text, "mem");
  ASSERT_TRUE(back.isovalue.has_value());
  EXPECT_EQ(back.isovalue->tau, -500.25);
  EXPECT_EQ(back.isovalue->inside, isotouch::core::InsideIs::kBelow);
  EXPECT_EQ(back.history_restarts, (std::vector<std::size_t>{2, 2, 7}));
  EXPECT_EQ(recording_text(back, "mem"), text);
  expect_refused(text, "\"inside\":\"below\"", "\"inside\":\"up\"",
          "bad.rec: line 1 (header): field 'isovalue.inside': must be \"above\" or \"below\", got \"up\"");
  expect_refused(text, "\"tau\":-500.25", "\"tau\":\"x\"", "field 'isovalue.tau'");
  expect_refused(text, "[2,2,7]", "[2,1]", "field 'history_restarts[1]': 1 is less than the one before it (2): must be ascending");
  expect_refused(text, "[2,2,7]", "[-1]", "field 'history_restarts[0]': must be an integer >= 0, got -1");
  expect_refused(text, "\"format_version\":3", "\"format_version\":2", "field 'history_restarts': unknown field");
  Recording two = random_recording(rng, 5, 0);
  two.history_restarts = {1};
  EXPECT_THROW((void)recording_text(two, "mem"), RecordingError);
}

// A FIFO named as a recording is refused before open() (which would wait for a writer).
TEST(Record, AFifoIsRefusedBeforeItIsOpened) {
  const fs::path d = temp_dir("fifo");
  const std::string f = (d / "f.rec").string();
  ASSERT_EQ(::mkfifo(f.c_str(), 0600), 0);
  try {
    (void)load_recording(f);
    ADD_FAILURE();
  } catch (const RecordingError& e) {
    EXPECT_EQ(std::string(e.what()), f + ": not a regular file (a FIFO): a recording is read from a regular file");
  }
}

TEST(Record, MissingFileIsNamed) {
  try {
    (void)load_recording("/nonexistent/dir/x.rec");
    ADD_FAILURE();
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/dir/x.rec: no such recording"), std::string::npos) << e.what();
  }
}

TEST(Record, GarbageNeverCrashesTheLoader) {
  // Corpus: random bytes; every prefix-cut and random byte flips of a good file; a few
  // hand-made nasties. parse_recording must return or throw RecordingError - any other
  // exception fails the test, a crash kills it.
  std::mt19937_64 rng(99);
  std::vector<std::string> corpus;
  const std::string good = small_text();
  for (std::size_t n = 0; n <= good.size(); n += 1 + n / 40) corpus.push_back(good.substr(0, n));
  for (int i = 0; i < 400; ++i) {
    std::string s = good;
    for (int f = 0, flips = 1 + int(rng() % 4); f < flips; ++f) s[rng() % s.size()] = char(rng());
    corpus.push_back(s);
  }
  for (int i = 0; i < 100; ++i) {
    std::string s(rng() % 300, '\0');
    for (char& ch : s) ch = char(rng());
    corpus.push_back(s);
  }
  corpus.push_back(std::string(100000, '[') + "\n");
  corpus.push_back(std::string(100000, '{') + "\n");
  corpus.push_back("{\"format\":\"isotouch-recording\",\"format_version\":18446744073709551615}\n");
  corpus.push_back("{\"format\":\"isotouch-recording\",\"format_version\":1,\"scene_path\":\"\\ud800\",\"scene_text\":\"\xff\xfe\",\"rate_hz\":1e308}\n");
  corpus.push_back(replaced(good, "{\"k\":0", "{\"k\":1e30"));
  corpus.push_back(replaced(good, "\"tick\":1", "\"tick\":-9223372036854775808"));
  corpus.push_back(std::string("\0\n\0\n", 4));
  long parsed = 0, refused = 0;
  for (const std::string& s : corpus) {
    try {
      (void)parse_recording(s, "garbage");
      ++parsed;
    } catch (const RecordingError& e) {
      ++refused;
      EXPECT_EQ(std::string(e.what()).rfind("garbage: ", 0), 0u) << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a RecordingError: " << e.what();
    }
  }
  EXPECT_GT(refused, 400);
  std::cout << "[ corpus   ] " << corpus.size() << " inputs: " << parsed << " parsed, " << refused << " refused\n";
}
