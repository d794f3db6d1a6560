// sparse_cpu.cpp - one-thread CPU reference of the sparse chain. STUB until the real one lands.
#include <stdexcept>

#include "sparse_chain.h"

namespace isotouch::engine {

SparseOutput run_sparse_cpu(const Volume& volume, const std::vector<PassDesc>&, const core::Isosurface&, float,
                            core::SampleFormat) {
  throw VolumeError(volume.path + ": run_sparse_cpu: not implemented yet");
}

}  // namespace isotouch::engine
