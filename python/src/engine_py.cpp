// engine_py.cpp - the engine from Python: a pass list run on a Vulkan device or on the CPU
// reference, its outputs as arrays, and `isotouch check --all`.
#include <atomic>
#include <memory>
#include <sstream>

#include "isotouch/bench/pass_check.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/python/common.h"
#include "isotouch/python/interruptible.h"
#include <pybind11/stl.h>

namespace isotouch::python {
namespace {

std::vector<engine::PassDesc> passes_arg(const py::object& passes) {
  if (passes.is_none()) return {engine::PassDesc::gradient()};
  std::vector<engine::PassDesc> out = passes.cast<std::vector<engine::PassDesc>>();
  if (const std::string why = engine::validate_passes(out); !why.empty()) throw py::value_error("passes: " + why);
  return out;
}

/// The chain on `device` ("cpu": the one-thread CPU reference, or `threads` of them; else a
/// Vulkan device by name substring or index, "" the default). Also returns the device's name.
engine::ChainOutput run_chain(const engine::Volume& v, const std::vector<engine::PassDesc>& passes,
                              const std::string& device, unsigned threads, std::string& device_name,
                              const std::atomic<bool>& cancel) {
  if (device == "cpu") {
    device_name = threads > 1 ? "CPU backend (" + std::to_string(threads) + " threads)" : "CPU reference";
    return engine::run_chain_cpu(v, passes, threads, &cancel);
  }
  engine::ContextOptions co;
  co.device = device;
  auto ctx = engine::VulkanContext::create(co);
  if (!ctx) throw std::runtime_error("Vulkan: " + ctx.error);
  device_name = (*ctx.value)->info().name;
  auto chain = engine::PassChain::create(**ctx.value, passes);
  if (!chain) throw std::runtime_error("Vulkan pass chain: " + chain.error);
  if (cancel.load()) throw engine::ChainCancelled("pass chain cancelled before its command buffer");
  return (*chain.value)->run(v);
}

py::dict run_passes(const std::shared_ptr<engine::Volume>& volume, const py::object& passes_in,
                    const std::string& device, unsigned threads, const py::object& tau, core::InsideIs inside) {
  const std::vector<engine::PassDesc> passes = passes_arg(passes_in);
  std::string name;
  // Ctrl-C stops the CPU chain within one axis sweep; a Vulkan chain's one command buffer
  // runs to its end.
  engine::ChainOutput out = run_interruptible(
      [&](const std::atomic<bool>& cancel) { return run_chain(*volume, passes, device, threads, name, cancel); });
  py::dict d;
  d["device"] = name;
  if (out.samples) {
    auto f = std::make_shared<core::SampleField>(std::move(*out.samples));
    if (!tau.is_none()) f->background = core::outside_background(*f, {tau.cast<double>(), inside});
    d["samples"] = f;
  }
  if (out.field) {
    const auto& g = volume->grid.dims;
    py::array_t<float> a({py::ssize_t(g[2]), py::ssize_t(g[1]), py::ssize_t(g[0])});
    std::copy(out.field->begin(), out.field->end(), a.mutable_data());
    d["field"] = a;
  }
  py::list timings;
  for (const engine::PassTiming& t : out.passes) timings.append(py::make_tuple(t.label, t.ms));
  d["timings_ms"] = timings;
  return d;
}

py::tuple check_all(const std::string& volume_path, const std::string& scene_path, const std::string& device,
                    double max_binding_mib) {
  const bench::CheckAllOptions o{
      .volume_path = volume_path, .scene_path = scene_path, .device = device, .max_binding_mib = max_binding_mib};
  std::ostringstream text;
  int rc = 0;
  {
    py::gil_scoped_release nogil;
    rc = bench::run_check_all(o, text);
  }
  return py::make_tuple(rc, text.str());
}

}  // namespace

void bind_engine(py::module_& m) {
  py::class_<engine::PassDesc>(m, "Pass", "one engine pass (engine/pass_desc.h)")
      .def_static("gaussian", &engine::PassDesc::gaussian, py::arg("sigma_mm"), "Gaussian, sigma [mm] > 0")
      .def_static("closing", &engine::PassDesc::closing, py::arg("radius_mm"), "closing, half-width [mm] >= 0")
      .def_static("gradient", &engine::PassDesc::gradient, "value + central-difference gradient samples")
      .def_static("brick_minmax", &engine::PassDesc::brick_minmax, py::arg("halo") = 1)
      .def_property_readonly("label", &engine::PassDesc::label)
      .def("__repr__", [](const engine::PassDesc& p) { return "<isotouch.Pass " + p.label() + ">"; });
  m.def("run_passes", &run_passes, py::arg("volume"), py::arg("passes") = py::none(), py::arg("device") = "cpu",
        py::arg("threads") = 1, py::arg("tau") = py::none(), py::arg("inside") = core::InsideIs::kAbove,
        R"(Run a pass list (default: [Pass.gradient()]) on `device`: 'cpu' the one-thread CPU reference
(threads > 1: the threaded CPU backend, the same bits), else a Vulkan device (name substring or
index; '' the default). GIL released; Ctrl-C stops a CPU chain within one axis sweep (a Vulkan
chain after its one command buffer) and raises KeyboardInterrupt. Returns a dict: 'samples' (a Field, with a gradient pass;
its background set for the isosurface when tau is given), 'field' ((nz, ny, nx) float32 after the
last filter, if any), 'timings_ms' [(label, ms)], 'device'.)");
  m.def("scene_passes", [](const std::string& scene_path) { return run::scene_passes(io::load_scene(scene_path)); },
        py::arg("scene"), "a scene file's engine.passes as a list of Pass (raises SceneError naming the field)");
  m.def("check_all", &check_all, py::arg("volume_path") = "", py::arg("scene_path") = "", py::arg("device") = "",
        py::arg("max_binding_mib") = 0.0,
        "`isotouch check --all`: every pass on the GPU against its CPU reference; returns (exit code, report text)");
}

}  // namespace isotouch::python
