// stability_report.h - `isotouch stability`: measured K_max against the passivity bound.
#pragma once
#include <iosfwd>
#include <string>

namespace isotouch::bench {

/// Sweep servo period T x device damping b (x virtual damping B) on a flat wall and a
/// sphere, find K_max (held contact neither sustains oscillation nor gains energy), with
/// and without the passivity controller; run the extreme cases. Writes DIR/stability.csv,
/// DIR/extreme_cases.csv, DIR/stability.png, DIR/stability.md. `quick` shortens runs.
/// @return 0 if every extreme case passed, 4 otherwise.
int run_stability(const std::string& out_dir, bool quick, std::ostream& log);

}  // namespace isotouch::bench
