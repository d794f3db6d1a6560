#include "isotouch/service/registration.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace isotouch::service {

bool Registration::is_identity() const {
  return r == std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1} && t_mm.x == 0 && t_mm.y == 0 && t_mm.z == 0;
}

std::string Registration::describe() const {
  std::ostringstream s;
  s << "rotation [";
  for (int i = 0; i < 3; ++i)
    s << (i ? " [" : "[") << r[std::size_t(3 * i)] << " " << r[std::size_t(3 * i + 1)] << " " << r[std::size_t(3 * i + 2)] << "]";
  s << "], translation (" << t_mm.x << ", " << t_mm.y << ", " << t_mm.z << ") mm";
  return s.str();
}

Registration registration_from_matrix(const double m[4][4]) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      if (!std::isfinite(m[i][j])) throw std::invalid_argument("registration: a matrix entry is not finite");
  if (std::abs(m[3][0]) > 1e-9 || std::abs(m[3][1]) > 1e-9 || std::abs(m[3][2]) > 1e-9 || std::abs(m[3][3] - 1) > 1e-9)
    throw std::invalid_argument("registration: the last row is not 0 0 0 1");
  Registration g;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) g.r[std::size_t(3 * i + j)] = m[i][j];
  double worst = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double d = 0;  // (R^T R)_ij
      for (int k = 0; k < 3; ++k) d += m[k][i] * m[k][j];
      worst = std::max(worst, std::abs(d - (i == j ? 1.0 : 0.0)));
    }
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  if (worst > 1e-3 || std::abs(det - 1) > 1e-3) {
    std::ostringstream s;
    s << "registration: not rigid (|R^T R - I| up to " << worst << ", det " << det
      << "): a rotation and a translation only, no scale, shear or mirror";
    throw std::invalid_argument(s.str());
  }
  g.t_mm = {m[0][3], m[1][3], m[2][3]};
  return g;
}

Registration load_registration(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot be read");
  std::vector<double> v;
  std::string line;
  while (std::getline(in, line)) {
    line = line.substr(0, line.find('#'));
    for (char& c : line)
      if (c == ',') c = ' ';
    std::istringstream s(line);
    std::string word;
    while (s >> word) {
      std::size_t used = 0;
      double x = 0;
      try {
        x = std::stod(word, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != word.size()) throw std::runtime_error(path + ": '" + word + "' is not a number");
      v.push_back(x);
    }
  }
  if (v.size() != 16 && v.size() != 12)
    throw std::runtime_error(path + ": " + std::to_string(v.size()) +
                             " numbers; a registration is a 4x4 matrix row by row (16, or 12 without 0 0 0 1)");
  double m[4][4] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 1}};
  for (std::size_t k = 0; k < v.size(); ++k) m[k / 4][k % 4] = v[k];
  try {
    return registration_from_matrix(m);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(path + ": " + e.what());
  }
}

}  // namespace isotouch::service
