// params_arg.h - a renderer's parameters from Python: the params object and the isovalue
// given beside it, resolved into one parameter struct (tau never silently 0).
#pragma once
#include <cmath>
#include <optional>
#include <sstream>
#include <string>

#include "isotouch/python/common.h"

namespace isotouch::python {

/// `params` as a P (None: the defaults, tau not given), its tau resolved with `tau`: either
/// one, or both when equal. @throws TypeError naming what was given and `expected`;
/// ValueError when no isovalue is given (`carrier`: what does not carry one) or two differ.
template <class P>
P params_arg(const py::object& params, const std::string& algorithm, const char* expected, std::optional<double> tau,
             const char* tau_name = "tau", const char* carrier = "a Field") {
  P p{};
  p.tau = std::nan("");
  if (!params.is_none()) {
    if (!py::isinstance<P>(params))
      throw py::type_error("params: " + std::string(py::str(py::type::of(params).attr("__name__"))) + " given for '" +
                           algorithm + "', expected isotouch." + expected);
    p = params.cast<P>();
  }
  if (tau) {
    if (!std::isfinite(*tau)) {
      std::ostringstream s;
      s << tau_name << ": " << *tau << " given, must be a finite isovalue (volume value units)";
      throw py::value_error(s.str());
    }
    if (!std::isnan(p.tau) && p.tau != *tau) {
      std::ostringstream s;
      s << tau_name << ": " << *tau << " given, but params.tau is " << p.tau << ": give the isovalue once";
      throw py::value_error(s.str());
    }
    p.tau = *tau;
  }
  if (!std::isfinite(p.tau))
    throw py::value_error("tau: no isovalue given for '" + algorithm + "' (" + carrier + " does not carry one): pass tau=" +
                          "VALUE (volume value units) or params=isotouch." + expected + "(tau=VALUE)");
  return p;
}

}  // namespace isotouch::python
