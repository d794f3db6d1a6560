// chain_cpu.cpp - the pass list (pass_desc.h): names, labels, its check, and the chain's
// CPU reference run_chain_cpu. No Vulkan (target isotouch::engine_cpu).
#include "isotouch/engine/pass_desc.h"

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/parallel.h"

namespace isotouch::engine {

namespace {
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
void stop_if_cancelled(const std::atomic<bool>* cancel, const std::string& where) {
  if (cancel && cancel->load(std::memory_order_relaxed)) throw ChainCancelled("pass chain cancelled before " + where);
}
}  // namespace

const char* pass_name(PassKind k) {
  switch (k) {
    case PassKind::Gaussian: return "gaussian";
    case PassKind::Closing: return "closing";
    case PassKind::Gradient: return "gradient";
    case PassKind::BrickMinMax: return "brick_minmax";
  }
  return "?";
}

std::string PassDesc::label() const {
  std::ostringstream s;
  s << pass_name(kind);
  if (kind == PassKind::Gaussian) s << "(sigma " << sigma_mm << " mm)";
  if (kind == PassKind::Closing) s << "(radius " << radius_mm << " mm)";
  if (kind == PassKind::BrickMinMax) s << "(halo " << halo << ")";
  return s.str();
}

std::string validate_passes(const std::vector<PassDesc>& p) {
  if (p.empty()) return "pass list is empty";
  int gradients = 0, minmax = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const std::string at = "pass " + std::to_string(i) + " (" + pass_name(p[i].kind) + "): ";
    switch (p[i].kind) {
      case PassKind::Gaussian:
        if (!(std::isfinite(p[i].sigma_mm) && p[i].sigma_mm > 0))
          return at + "sigma_mm must be finite and > 0, got " + std::to_string(p[i].sigma_mm);
        break;
      case PassKind::Closing:
        if (!(std::isfinite(p[i].radius_mm) && p[i].radius_mm >= 0))
          return at + "radius_mm must be finite and >= 0, got " + std::to_string(p[i].radius_mm);
        break;
      case PassKind::Gradient:
        if (++gradients > 1) return at + "gradient may appear once";
        break;
      case PassKind::BrickMinMax:
        if (++minmax > 1) return at + "brick_minmax may appear once";
        if (p[i].halo < 0 || p[i].halo > 8) return at + "halo must be 0..8, got " + std::to_string(p[i].halo);
        break;
    }
  }
  return {};
}

ChainOutput run_chain_cpu(const Volume& vol, const std::vector<PassDesc>& passes, unsigned threads,
                          const std::atomic<bool>* cancel) {
  if (std::string e = validate_passes(passes); !e.empty()) throw std::invalid_argument("pass chain: " + e);
  threads = threads_for(vol.grid.voxel_count(), threads);
  ChainOutput out;
  Volume cur = vol;
  bool filtered = false;
  const auto total0 = std::chrono::steady_clock::now();
  for (const PassDesc& p : passes) {
    PassTiming pt;
    pt.label = p.label();
    stop_if_cancelled(cancel, pt.label);
    const auto t0 = std::chrono::steady_clock::now();
    switch (p.kind) {
      case PassKind::Gaussian: {
        const GaussianAxes a = gaussian_axes(cur.grid, p.sigma_mm);
        std::vector<float> tmp;
        for (int axis = 0; axis < 3; ++axis) {
          if (axis > 0) stop_if_cancelled(cancel, pt.label + "'s axis " + std::to_string(axis));
          gaussian_axis_cpu(cur.voxels, tmp, cur.grid, axis, a.kernel[std::size_t(axis)], threads);
          cur.voxels.swap(tmp);
        }
        filtered = true;
        break;
      }
      case PassKind::Closing: {
        const auto r = closing_radii(cur.grid, p.radius_mm);
        std::vector<float> tmp;
        for (int k = 0; k < 6; ++k) {
          if (k > 0) stop_if_cancelled(cancel, pt.label + "'s sweep " + std::to_string(k));
          morph_axis_cpu(cur.voxels, tmp, cur.grid, k % 3, r[std::size_t(k % 3)], k < 3, threads);
          cur.voxels.swap(tmp);
        }
        filtered = true;
        break;
      }
      case PassKind::Gradient: out.samples = compute_samples_cpu(cur, threads); break;
      case PassKind::BrickMinMax: out.bricks = brick_minmax_cpu(cur, p.halo, threads); break;
    }
    pt.ms = ms_since(t0);
    out.passes.push_back(pt);
  }
  out.submit_wall_ms = ms_since(total0);
  if (filtered) out.field = std::move(cur.voxels);
  return out;
}

}  // namespace isotouch::engine
