// The force-direction steps of a run's contact ticks (run/trace_figures.h): angles between
// analytic force vectors, a flip through a zero force, and a contact that ends; and the
// first-order estimate kept only where it is a distance.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/run/stroke_warning.h"
#include "isotouch/run/trace_figures.h"

using isotouch::core::Vec3;
using isotouch::run::DirectionSteps;

TEST(DirectionSteps, AnglesBetweenConsecutiveContactForces) {
  DirectionSteps d;
  d.add(0.000, true, {0, 0, 1});
  d.add(0.001, true, {0, 0, 2});        // same direction: 0 deg
  d.add(0.002, true, {1, 0, 1});        // 45 deg
  d.add(0.003, true, {0, 3, 0});        // 90 deg from (1, 0, 1)
  EXPECT_EQ(d.pairs, 3);
  EXPECT_NEAR(d.max_deg, 90.0, 1e-9);
  EXPECT_DOUBLE_EQ(d.max_t_s, 0.003);
  EXPECT_NEAR(d.rms_deg(), std::sqrt((0.0 + 45.0 * 45.0 + 90.0 * 90.0) / 3.0), 1e-9);
}

// A wall that would pull sends zero: the direction that flips through that tick is a step
// of 180 deg from the last force sent, not two steps skipped.
TEST(DirectionSteps, AFlipThroughAZeroForceCounts) {
  DirectionSteps d;
  d.add(0.000, true, {0, 0, 1});
  d.add(0.001, true, {0, 0, 0});
  d.add(0.002, true, {0, 0, -1});
  EXPECT_EQ(d.pairs, 1);
  EXPECT_NEAR(d.max_deg, 180.0, 1e-9);
  EXPECT_DOUBLE_EQ(d.max_t_s, 0.002);
}

// Out of contact in between: two contacts, no step between them.
TEST(DirectionSteps, AContactThatEndsStartsAfresh) {
  DirectionSteps d;
  d.add(0.000, true, {0, 0, 1});
  d.add(0.001, false, {0, 0, 0});
  d.add(0.002, true, {0, 0, -1});
  EXPECT_EQ(d.pairs, 0);
  EXPECT_EQ(d.max_deg, 0.0);
  EXPECT_EQ(d.rms_deg(), 0.0);
}

// The first-order estimate |f - tau| / |grad f| is a distance only where it is finite and no
// longer than the volume's diagonal; where |grad f| is near 0 (a flat field) it is left out.
TEST(FirstOrderEstimate, IsADistanceOnlyWithinTheVolume) {
  using isotouch::run::first_order_as_distance;
  const double diagonal_m = 0.1;
  EXPECT_EQ(first_order_as_distance(0.0, diagonal_m), 0.0);
  EXPECT_EQ(first_order_as_distance(2e-4, diagonal_m), 2e-4);
  EXPECT_EQ(first_order_as_distance(0.1, diagonal_m), 0.1);
  EXPECT_FALSE(first_order_as_distance(0.1000001, diagonal_m));
  EXPECT_FALSE(first_order_as_distance(3.9e11, diagonal_m)) << "|grad f| near 0: 3.9e14 mm";
  EXPECT_FALSE(first_order_as_distance(INFINITY, diagonal_m));
  EXPECT_FALSE(first_order_as_distance(NAN, diagonal_m));
}

// The run's warning: under half the stroke's ticks in contact, with the figures; not at half.
TEST(StrokeWarning, UnderHalfTheStrokeInContactIsWarnedWithItsFigures) {
  isotouch::run::RunMetrics m;
  m.stroke_ticks = 1000;
  m.stroke_contact_ticks = 499;
  const std::string w = isotouch::run::stroke_contact_warning(m);
  EXPECT_NE(w.find("499 of its 1000 ticks"), std::string::npos) << w;
  EXPECT_NE(w.find("49.9 %"), std::string::npos) << w;
  m.stroke_contact_ticks = 500;
  EXPECT_EQ(isotouch::run::stroke_contact_warning(m), "");
  m.stroke_ticks = m.stroke_contact_ticks = 0;  // no stroke in the script: nothing to warn about
  EXPECT_EQ(isotouch::run::stroke_contact_warning(m), "");
}
