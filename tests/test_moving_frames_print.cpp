// bench/moving_frames.h's printed verdicts on results the test makes: the refinement bands'
// largest against the frame budget (each band is a frame), named with its band and rows.
#include "isotouch/bench/moving_frames.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>

namespace {
using isotouch::bench::MovingFramesOptions;
using isotouch::bench::MovingFramesResult;

/// 60 moving frames of 20 ms at scale 0.5, stopped and refined in `ms` bands of `rows`.
std::string printed(const std::vector<double>& ms, const std::vector<int>& rows, double budget_ms = 33) {
  MovingFramesResult r;
  r.ms.assign(60, 20.0);
  r.render_ms.assign(60, 15.0);
  r.scales.assign(60, 0.5);
  r.still.ms = ms;
  r.still.rows = rows;
  r.still.equal = true;
  r.still_frames = int(ms.size());
  r.still_to_full_ms = r.still.total_ms();
  MovingFramesOptions o;
  o.budget_ms = budget_ms;
  std::ostringstream out;
  isotouch::bench::print_moving_frames(out, r, o, 1920, 1440);
  return out.str();
}

TEST(MovingFramesPrint, TheLargestBandAgainstTheBudget) {
  const std::string over = printed({2.5, 40.25, 12.0}, {1, 700, 739});
  EXPECT_NE(over.find("verdict: refinement bands: the largest 40.2 ms (band 2 of 3, 700 of 1440 rows): each <= 33.0 ms "
                      "(the frame budget): NOT met\n"),
            std::string::npos)
      << over;
  EXPECT_NE(over.find("verdict: view stopped to full resolution 54.8 ms (3 frames in bands of rows): target <= 250 ms: met; "
                      "the full frame bit for bit: yes\n"),
            std::string::npos)
      << over;
  const std::string within = printed({2.5, 30.0, 33.0, 12.0}, {1, 500, 600, 339});
  EXPECT_NE(within.find("verdict: refinement bands: the largest 33.0 ms (band 3 of 4, 600 of 1440 rows): each <= 33.0 ms "
                        "(the frame budget): met\n"),
            std::string::npos)
      << within;
  // Against another budget: the same bands.
  EXPECT_NE(printed({2.5, 30.0, 33.0, 12.0}, {1, 500, 600, 339}, 30).find("each <= 30.0 ms (the frame budget): NOT met\n"),
            std::string::npos);
}

TEST(MovingFramesPrint, NoBandsWhenTheLastMovingFrameWasWhole) {
  const std::string none = printed({}, {});
  EXPECT_NE(none.find("verdict: refinement bands: none (drawn whole while moving): each <= 33.0 ms (the frame budget): met\n"),
            std::string::npos)
      << none;
  EXPECT_EQ(none.find("moving   the bands"), std::string::npos);
}

}  // namespace
