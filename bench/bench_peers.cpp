// bench_peers.cpp - see bench_peers.h. The only translation unit of `bench engine` that
// includes ITK's filters and OpenVDB's tools.
#include "isotouch/bench/bench_peers.h"

#include <chrono>
#include <cstring>
#include <exception>

#include <itkDiscreteGaussianImageFilter.h>
#include <itkGradientImageFilter.h>
#include <itkImage.h>
#include <itkMultiThreaderBase.h>

#ifdef ISOTOUCH_HAVE_OPENVDB
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/GridOperators.h>
#include <tbb/global_control.h>
#endif

#include "isotouch/core/sample_field.h"

namespace isotouch::bench {
namespace {
using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}
using FloatImage = itk::Image<float, 3>;

FloatImage::Pointer to_itk(const engine::Volume& v) {
  auto img = FloatImage::New();
  FloatImage::RegionType region;
  FloatImage::SizeType size;
  for (unsigned a = 0; a < 3; ++a) size[a] = itk::SizeValueType(v.grid.dims[a]);
  region.SetSize(size);
  img->SetRegions(region);
  FloatImage::SpacingType sp;
  sp[0] = v.grid.spacing_m.x * 1e3;
  sp[1] = v.grid.spacing_m.y * 1e3;
  sp[2] = v.grid.spacing_m.z * 1e3;
  img->SetSpacing(sp);
  img->Allocate();
  std::memcpy(img->GetBufferPointer(), v.voxels.data(), v.voxels.size() * sizeof(float));
  return img;
}
}  // namespace

PeerTimes run_peers_once(const engine::Volume& v, double sigma_mm, int threads) {
  PeerTimes t;
  FloatImage::Pointer smoothed;
  try {
    itk::MultiThreaderBase::SetGlobalDefaultNumberOfThreads(threads);
    itk::MultiThreaderBase::SetGlobalMaximumNumberOfThreads(threads);
    FloatImage::Pointer img = to_itk(v);
    using Gauss = itk::DiscreteGaussianImageFilter<FloatImage, FloatImage>;
    auto g = Gauss::New();
    g->SetInput(img);
    g->SetVariance(sigma_mm * sigma_mm);
    g->SetUseImageSpacing(true);
    g->SetMaximumKernelWidth(129);
    g->SetNumberOfWorkUnits(unsigned(threads));
    g->GetMultiThreader()->SetMaximumNumberOfThreads(unsigned(threads));
    auto t0 = Clock::now();
    g->Update();
    t.itk_gaussian_ms = ms_since(t0);
    smoothed = g->GetOutput();
    using Grad = itk::GradientImageFilter<FloatImage, float, float>;
    auto d = Grad::New();
    d->SetInput(smoothed);
    d->SetUseImageSpacing(true);
    d->SetNumberOfWorkUnits(unsigned(threads));
    d->GetMultiThreader()->SetMaximumNumberOfThreads(unsigned(threads));
    t0 = Clock::now();
    d->Update();
    t.itk_gradient_ms = ms_since(t0);
    // The published form: value and gradient [value / m] in one 16-byte sample per voxel.
    t0 = Clock::now();
    const std::size_t n = v.voxels.size();
    std::vector<core::Sample> out(n);
    const float* val = smoothed->GetBufferPointer();
    const auto* grad = d->GetOutput()->GetBufferPointer();
    for (std::size_t i = 0; i < n; ++i)
      out[i] = {val[i], grad[i][0] * 1e3f, grad[i][1] * 1e3f, grad[i][2] * 1e3f};
    t.itk_pack_ms = ms_since(t0);
    volatile float sink = out[n / 2].gx;
    (void)sink;
  } catch (const std::exception& e) {
    t.itk_why = std::string("ITK: ") + e.what();
  }
#ifdef ISOTOUCH_HAVE_OPENVDB
  try {
    openvdb::initialize();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    const int nx = v.grid.dims[0], ny = v.grid.dims[1], nz = v.grid.dims[2];
    const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(nx - 1, ny - 1, nz - 1));
    // x fastest, as in engine::Volume: OpenVDB's LayoutXYZ. The Gaussian's output when ITK
    // ran (the chain's input to the gradient), else the raw voxels.
    std::vector<float> src = v.voxels;
    if (smoothed) std::memcpy(src.data(), smoothed->GetBufferPointer(), src.size() * sizeof(float));
    openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(box, src.data());
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(v.grid.spacing_m.x));
    auto t0 = Clock::now();
    openvdb::tools::copyFromDense(dense, *grid, 0.0f, false);
    t.vdb_from_dense_ms = ms_since(t0);
    t0 = Clock::now();
    auto g = openvdb::tools::gradient(*grid, true);
    t.vdb_gradient_ms = ms_since(t0);
    volatile auto sink = g->activeVoxelCount();
    (void)sink;
  } catch (const std::exception& e) {
    t.vdb_why = std::string("OpenVDB: ") + e.what();
  }
#else
  t.vdb_why = "OpenVDB not built in (libopenvdb-dev not found at configure time)";
#endif
  return t;
}

}  // namespace isotouch::bench
