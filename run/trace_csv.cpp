#include "isotouch/run/trace_csv.h"
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>
#include "isotouch/core/vec3.h"

namespace isotouch::run {
namespace fs = std::filesystem;
using core::Vec3;

// One row per tick; points and forces in the volume's physical frame
// (world = origin + D (spacing * index)), not the grid frame the servo works in.
std::string trace_csv(const std::vector<sim::TraceRow>& trace, const engine::Volume& vol) {
  std::ostringstream s;
  s << "t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m,vhip_y_m,vhip_z_m,f_x_n,f_y_n,f_z_n,contact,"
       "plane_update,tick_ns\n";
  s << std::setprecision(9);
  for (const auto& r : trace) {
    const Vec3 hip = vol.to_physical(r.hip_m), vhip = vol.to_physical(r.vhip_m);
    const Vec3 f = vol.direction_apply(r.force_n);
    s << r.t_s << ',' << hip.x << ',' << hip.y << ',' << hip.z << ',' << vhip.x << ',' << vhip.y << ','
      << vhip.z << ',' << f.x << ',' << f.y << ',' << f.z << ',' << int(r.contact) << ','
      << int(r.plane_update) << ',' << r.tick_ns << '\n';
  }
  return s.str();
}

std::vector<sim::TraceRow> read_trace_csv(const std::string& path, const engine::Volume& vol) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read the trace");
  std::string line;
  if (!std::getline(in, line) || line.rfind("t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m", 0) != 0)
    throw std::runtime_error(path + ": not an isotouch trace.csv (header 't_s,hip_x_m,...' expected)");
  const auto& D = vol.direction;
  std::vector<sim::TraceRow> rows;
  long lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty()) continue;
    double v[11];
    std::size_t pos = 0;
    for (int c = 0; c < 11; ++c) {
      const std::size_t end = line.find(',', pos);
      const std::string cell = line.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
      char* stop = nullptr;
      v[c] = std::strtod(cell.c_str(), &stop);
      if (cell.empty() || stop != cell.c_str() + cell.size())
        throw std::runtime_error(path + ": line " + std::to_string(lineno) + ", column " + std::to_string(c + 1) +
                                 ": not a number: '" + cell + "'");
      if (!std::isfinite(v[c]))  // strtod reads "nan" and "inf": a trace never holds them
        throw std::runtime_error(path + ": line " + std::to_string(lineno) + ", column " + std::to_string(c + 1) +
                                 ": not a finite number: '" + cell + "'");
      if (end == std::string::npos && c < 10)
        throw std::runtime_error(path + ": line " + std::to_string(lineno) + ": " + std::to_string(c + 1) +
                                 " columns, at least 11 expected");
      pos = end + 1;
    }
    sim::TraceRow r;
    r.t_s = v[0];
    r.hip_m = vol.to_grid({v[1], v[2], v[3]});
    r.vhip_m = vol.to_grid({v[4], v[5], v[6]});
    const Vec3 f{v[7], v[8], v[9]};  // physical -> grid-world: D^T f
    r.force_n = {D[0] * f.x + D[3] * f.y + D[6] * f.z, D[1] * f.x + D[4] * f.y + D[7] * f.z,
                 D[2] * f.x + D[5] * f.y + D[8] * f.z};
    r.contact = v[10] != 0;
    rows.push_back(r);
  }
  if (rows.empty()) throw std::runtime_error(path + ": no rows");
  return rows;
}

// ---- isotouch render -----------------------------------------------------------------

}  // namespace isotouch::run
