// bench_engine.cpp - `isotouch bench engine`. See bench_engine.h.
#include "isotouch/bench/servo_bench.h"
#include "isotouch/bench/bench_engine.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <tuple>

#include "isotouch/bench/bench_peers.h"
#include "isotouch/core/field_view.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/io/files.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/pool_recycler.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::bench {
using eval::median;
using io::write_file_atomic;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}
}  // namespace

// ---------------------------------------------------------------------------------------
// Formulas

std::uint64_t pass_min_bytes(engine::PassKind kind, std::uint64_t voxels, std::uint64_t bricks) {
  switch (kind) {
    case engine::PassKind::Gaussian:
    case engine::PassKind::Closing: return voxels * 4 + voxels * 4;
    case engine::PassKind::Gradient: return voxels * 4 + voxels * sizeof(core::Sample);
    case engine::PassKind::BrickMinMax: return voxels * 4 + bricks * 8;
  }
  return 0;
}

double gb_per_s(double bytes, double ms) {
  if (!(ms > 0) || !std::isfinite(ms)) return kNaN;
  return bytes / (ms * 1e-3) / 1e9;
}

double measure_memcpy_gbps(std::size_t bytes, int tries) {
  std::vector<unsigned char> src(bytes), dst(bytes);
  for (std::size_t i = 0; i < bytes; i += 64) src[i] = static_cast<unsigned char>(i >> 6);
  std::memset(dst.data(), 1, bytes);  // fault every page in before timing
  double best_ms = std::numeric_limits<double>::infinity();
  for (int t = 0; t < std::max(1, tries); ++t) {
    const auto t0 = Clock::now();
    std::memcpy(dst.data(), src.data(), bytes);
    best_ms = std::min(best_ms, ms_since(t0));
  }
  volatile unsigned char sink = dst[bytes / 2];  // keep the copy
  (void)sink;
  return gb_per_s(2.0 * double(bytes), best_ms);
}

double ratio(double a, double b) {
  if (!std::isfinite(a) || !std::isfinite(b) || !(b > 0)) return kNaN;
  return a / b;
}

// ---------------------------------------------------------------------------------------
// Verdicts

Verdict verdict_at_most(const std::string& what, double value, double target, int digits,
                        const std::string& why_missing) {
  Verdict v;
  std::ostringstream o;
  o << std::fixed << std::setprecision(digits);
  if (!std::isfinite(value)) {
    o << what << ": not measured" << (why_missing.empty() ? "" : " (" + why_missing + ")") << "; target <= "
      << target;
    v.text = o.str();
    return v;
  }
  v.measured = true;
  v.met = value <= target;
  o << what << " = " << value << ": target <= " << target << (v.met ? " met" : " NOT met");
  v.text = o.str();
  return v;
}

// ---------------------------------------------------------------------------------------
// Child processes

namespace {
// Parent side: read the child's stdout to EOF, reap it with wait4.
ChildRun collect(pid_t pid, int out_fd, Clock::time_point t0) {
  ChildRun r;
  r.started = true;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(out_fd, buf, sizeof buf);
    if (n > 0) {
      r.out.append(buf, std::size_t(n));
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    break;
  }
  ::close(out_fd);
  int status = 0;
  rusage ru{};
  pid_t w;
  do w = ::wait4(pid, &status, 0, &ru);
  while (w < 0 && errno == EINTR);
  r.wall_ms = ms_since(t0);
  if (w < 0) {
    r.error = std::string("wait4: ") + std::strerror(errno);
    return r;
  }
  r.peak_rss_bytes = std::uint64_t(ru.ru_maxrss) * 1024;  // Linux: KiB
  r.cpu_s = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  if (WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  return r;
}
}  // namespace

ChildRun run_child_fork(const std::function<int()>& body) {
  int p[2];
  if (::pipe2(p, O_CLOEXEC) != 0) return {false, -1, 0, kNaN, 0, {}, std::string("pipe: ") + std::strerror(errno)};
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  const auto t0 = Clock::now();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(p[0]);
    ::close(p[1]);
    return {false, -1, 0, kNaN, 0, {}, std::string("fork: ") + std::strerror(errno)};
  }
  if (pid == 0) {
    ::dup2(p[1], STDOUT_FILENO);
    ::close(p[0]);
    int rc = 1;
    try {
      rc = body();
    } catch (...) {
      rc = 1;
    }
    std::cout.flush();
    std::fflush(nullptr);
    ::_exit(rc);
  }
  ::close(p[1]);
  return collect(pid, p[0], t0);
}

ChildRun run_child_exec(const std::vector<std::string>& argv) {
  if (argv.empty()) return {false, -1, 0, kNaN, 0, {}, "no program"};
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  // The forked child (stdout already on the pipe) replaces itself; 127 if execv fails.
  ChildRun r = run_child_fork([&] {
    ::execv(args[0], args.data());
    return 127;
  });
  if (r.exit_code == 127) r.error = "could not execute " + argv[0] + " (exit 127)";
  return r;
}

std::uint64_t self_peak_rss_bytes() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::uint64_t(std::stoull(line.substr(6))) * 1024;  // "... kB"
  return 0;
}

std::map<std::string, std::string> parse_key_values(const std::string& text) {
  std::map<std::string, std::string> kv;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const auto eq = line.find('=');
    if (eq == std::string::npos || eq == 0) continue;
    kv[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return kv;
}

// ---------------------------------------------------------------------------------------
// Volumes

namespace {
std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}
}  // namespace

engine::Volume make_noisy_sphere(int n, double spacing_m, double noise_mm, std::uint32_t seed) {
  engine::Volume v = engine::make_sphere({n, n, n}, spacing_m, 0.375 * n);
  const std::uint64_t s = std::uint64_t(seed) << 40;
  for (std::size_t i = 0; i < v.voxels.size(); ++i) {
    const double u = double(splitmix64(s ^ i) >> 40) / double(1ull << 24);  // [0, 1)
    v.voxels[i] += float((2.0 * u - 1.0) * noise_mm);
  }
  v.update_stats();
  std::ostringstream name;
  name << "synthetic:noisy-sphere(" << n << "^3, r=" << 0.375 * n << " vox, noise +-" << noise_mm << " mm)";
  v.path = name.str();
  return v;
}

std::vector<engine::PassDesc> sparse_list(bool with_closing) {
  std::vector<engine::PassDesc> l = {engine::PassDesc::gaussian(1.0)};
  if (with_closing) l.push_back(engine::PassDesc::closing(1.0));
  l.push_back(engine::PassDesc::gradient());
  return l;
}

std::vector<engine::PassDesc> dense_list(bool with_closing) {
  auto l = sparse_list(with_closing);
  l.push_back(engine::PassDesc::brick_minmax(1));
  return l;
}

// ---------------------------------------------------------------------------------------
// One case

namespace {
std::string list_label(const std::vector<engine::PassDesc>& l) {
  std::string s;
  for (const auto& p : l) s += (s.empty() ? "" : " + ") + p.label();
  return s;
}

std::string format_name(core::SampleFormat f) {
  switch (f) {
    case core::SampleFormat::kFp32: return "fp32";
    case core::SampleFormat::kFp16: return "fp16";
    case core::SampleFormat::kUnorm16: return "unorm16";
  }
  return "?";
}

// Timed samples of one sparse engine at one isovalue.
struct SparseSamples {
  bool ok = true;
  std::string why;
  std::vector<double> total;
  std::vector<std::vector<double>> stage;
  std::vector<std::string> labels;
  engine::SparseStats stats;
  void add(const engine::SparseOutput& o) {
    total.push_back(o.total_ms);
    if (stage.size() < o.passes.size()) stage.resize(o.passes.size());
    labels.resize(std::max(labels.size(), o.passes.size()));
    for (std::size_t i = 0; i < o.passes.size(); ++i) {
      stage[i].push_back(o.passes[i].ms >= 0 ? o.passes[i].ms : kNaN);
      labels[i] = o.passes[i].label;
    }
    stats = o.stats;
  }
  SparseCell cell() const {
    SparseCell c;
    c.available = ok && !total.empty();
    c.why = ok ? (total.empty() ? "no run" : "") : why;
    if (!c.available) return c;
    c.total_ms = median(total);
    c.stage_labels = labels;
    for (const auto& s : stage) c.stage_ms.push_back(median(s));
    c.stats = stats;
    return c;
  }
};

// Runs `f` and records a failure in `s` instead of throwing.
template <class F>
void guarded(SparseSamples& s, F&& f) {
  if (!s.ok) return;
  try {
    f();
  } catch (const std::exception& e) {
    s.ok = false;
    s.why = e.what();
  }
}
}  // namespace

namespace {
using FloorTraffic = engine::GradientPass::FloorTraffic;

/// The copy floors (copy_x4.comp) of each traffic a dense pass has, sampled once per
/// repetition beside the chain (the same load on the machine), device time [ms].
struct FloorSamples {
  engine::GradientPass pass;
  std::map<FloorTraffic, std::vector<double>> ms;
  explicit FloorSamples(engine::VulkanContext& ctx) : pass(ctx) {}
  void sample(const engine::Volume& v) {
    for (FloorTraffic t : {FloorTraffic::Samples, FloorTraffic::Floats, FloorTraffic::ReadOnly})
      ms[t].push_back(pass.copy_floor_ms(v, 1, t));
  }
  double median_of(FloorTraffic t) const { return ms.count(t) ? median(ms.at(t)) : kNaN; }
};

/// The dense chain's floors from the copy floors' medians: per pass the floor of its loads
/// and stores, summed - once per pass (the chain's bytes: `first`) and once per pass over
/// the field as the chain runs them (`second`: a Gaussian's x, y and z passes, a closing's six).
std::pair<double, double> chain_floor_ms(const FloorSamples& floors, const std::vector<engine::PassDesc>& passes) {
  double bytes = 0, as_run = 0;
  for (const engine::PassDesc& p : passes) {
    const FloorTraffic t = p.kind == engine::PassKind::Gradient      ? FloorTraffic::Samples
                           : p.kind == engine::PassKind::BrickMinMax ? FloorTraffic::ReadOnly
                                                                     : FloorTraffic::Floats;  // one filter pass
    const double ms = floors.median_of(t);
    bytes += ms;
    const int field_passes = p.kind == engine::PassKind::Gaussian ? 3 : p.kind == engine::PassKind::Closing ? 6 : 1;
    as_run += field_passes * ms;
  }
  return {bytes, as_run};
}
}  // namespace

namespace {
/// The chain's passes' device times summed [ms] (NaN where one has no time).
double passes_ms(const engine::ChainOutput& g, std::size_t np) {
  double sum = 0;
  for (std::size_t i = 0; i < np && i < g.passes.size(); ++i) sum += g.passes[i].ms >= 0 ? g.passes[i].ms : kNaN;
  return sum;
}

/// Pairs of the chain and the standalone set run back to back beside each repetition's pair
/// (kExtraPairs more, the order alternating), so that the chain / set ratio is a median of
/// ratios of runs at the same moment's load rather than a ratio of medians of three.
constexpr int kExtraPairs = 6;
void extra_pairs(engine::PassChain& chain, StandaloneSet& set, const engine::Volume& v, std::size_t np, int rep,
                 std::vector<double>& chain_pair_ms) {
  for (int k = 0; k < kExtraPairs; ++k) {
    const bool set_first = (rep + k) % 2;
    if (set_first) set.run();
    chain_pair_ms.push_back(passes_ms(chain.run(v), np));
    if (!set_first) set.run();
  }
}

/// The median over pairs of chain[i] / set[i], skipping pairs without a finite ratio (a set
/// run whose faster brick min/max form ran untimed); NaN without such pairs, or if the two
/// lists do not match.
double paired_ratio(const std::vector<double>& chain, const std::vector<double>& set) {
  if (chain.size() != set.size()) return kNaN;
  std::vector<double> r;
  for (std::size_t i = 0; i < chain.size(); ++i)
    if (const double x = ratio(chain[i], set[i]); std::isfinite(x)) r.push_back(x);
  return r.empty() ? kNaN : median(r);
}

/// The standalone pass set of a case (the list without closing: the same work as the dense
/// chain), or null with r.standalone.why saying why not.
std::unique_ptr<StandaloneSet> make_standalone(engine::VulkanContext* ctx, bool chain, const engine::Volume& v,
                                               const std::vector<engine::PassDesc>& dense, bool with_closing,
                                               CaseResult& r) {
  if (!ctx || !chain) {
    r.standalone.why = "no GPU chain";
    return nullptr;
  }
  if (with_closing) {
    r.standalone.why = "not run with the closing (the set is the list without it)";
    return nullptr;
  }
  try {
    return std::make_unique<StandaloneSet>(*ctx, v, dense.front().sigma_mm);
  } catch (const std::exception& e) {
    r.standalone.why = e.what();
    return nullptr;
  }
}
}  // namespace

CaseResult run_case(engine::VulkanContext* ctx, const std::string& gpu_why, const BenchCase& c, bool with_closing,
                    int repetitions, double memcpy_gbps, std::ostream& progress, bool peers) {
  const engine::Volume& v = *c.volume;
  const auto dense = dense_list(with_closing), sparse = sparse_list(with_closing);
  CaseResult r;
  r.name = c.name;
  r.source = c.source;
  r.list_label = list_label(dense);
  r.dims = v.grid.dims;
  r.voxels = v.grid.voxel_count();
  const auto bc = core::brick_counts(v.grid);
  r.bricks = std::uint64_t(bc[0]) * std::uint64_t(bc[1]) * std::uint64_t(bc[2]);
  r.memcpy_gbps = memcpy_gbps;
  r.gpu_why = gpu_why;

  std::unique_ptr<engine::PassChain> chain, legacy;
  std::unique_ptr<engine::SparseChain> schain, sdense, sbrick;
  std::string sparse_why = gpu_why;
  if (ctx) {
    try {
      auto cr = engine::PassChain::create(*ctx, dense);
      if (cr) chain = std::move(*cr.value);
      else r.gpu_why = cr.error;
      auto lr = engine::PassChain::create(*ctx, dense, engine::ShaderSet::Legacy);
      if (lr) legacy = std::move(*lr.value);
    } catch (const std::exception& e) {
      r.gpu_why = e.what();
    }
    try {
      auto sr = engine::SparseChain::create(*ctx, sparse);
      if (sr) schain = std::move(*sr.value);
      auto dr = engine::SparseChain::create(*ctx, sparse);
      if (dr) {
        sdense = std::move(*dr.value);
        sdense->set_strategy(engine::SparseChain::Strategy::Dense);
      }
      auto br = engine::SparseChain::create(*ctx, sparse);
      if (br) {
        sbrick = std::move(*br.value);
        sbrick->set_strategy(engine::SparseChain::Strategy::PerBrick);
      }
      else sparse_why = sr.error;
    } catch (const std::exception& e) {
      sparse_why = e.what();
    }
  }
  std::unique_ptr<StandaloneSet> standalone = make_standalone(ctx, chain != nullptr, v, dense, with_closing, r);
  // The device's copy floors, sampled in each repetition beside the chain.
  std::unique_ptr<FloorSamples> floors = chain ? std::make_unique<FloorSamples>(*ctx) : nullptr;
  const std::size_t np = dense.size(), ni = c.isos.size();
  std::vector<std::vector<double>> gpu_ms(np), cpu_ms(np), legacy_ms(np);
  std::vector<double> gpu_wall, cpu_wall, legacy_wall, cpu_mt_wall;
  r.cpu_backend_threads = engine::hardware_threads();
  double sigma_mm = kNaN;
  for (const auto& p : dense)
    if (p.kind == engine::PassKind::Gaussian) sigma_mm = p.sigma_mm;
  const bool run_peers = peers && std::isfinite(sigma_mm);
  std::vector<PeerTimes> peer_runs[2];
  std::vector<SparseSamples> sg(ni), sc(ni), sb(ni), sd(ni), smt(ni);
  std::vector<float> bg(ni);
  for (std::size_t k = 0; k < ni; ++k) {
    bg[k] = float(c.isos[k].outside_value(v.min_value, v.max_value));
    if (!schain) sg[k] = {false, sparse_why.empty() ? "no GPU" : sparse_why, {}, {}, {}, {}};
    if (!sbrick) sb[k] = {false, sparse_why.empty() ? "no GPU" : sparse_why, {}, {}, {}, {}};
    if (!sdense) sd[k] = {false, sparse_why.empty() ? "no GPU" : sparse_why, {}, {}, {}, {}};
  }
  // Warm-up (untimed): first dispatches, allocations, lazy pipeline compiles.
  if (chain) {
    progress << "[bench engine] " << c.name << ": warm-up\n" << std::flush;
    try {
      (void)chain->run(v);
      if (legacy) (void)legacy->run(v);
      if (standalone) standalone->run(false);
    } catch (const std::exception& e) {
      r.gpu_why = e.what();
      chain.reset();
      legacy.reset();
    }
  }
  for (std::size_t k = 0; k < ni; ++k) {
    guarded(sg[k], [&] { (void)schain->run(v, c.isos[k], bg[k]); });
    guarded(sb[k], [&] { (void)sbrick->run(v, c.isos[k], bg[k]); });
    guarded(sd[k], [&] { (void)sdense->run(v, c.isos[k], bg[k]); });
  }

  // The sparse CPU engines publish into recycled pools too (as the GPU chain: a run per
  // isovalue, pages resident), each engine its own recycler.
  std::vector<double> chain_pair_ms;  // the chain's device time in each run paired with the set's
  const auto cpu_pools = std::make_shared<engine::PoolRecycler>();
  const auto cpu_mt_pools = std::make_shared<engine::PoolRecycler>();
  for (int rep = 0; rep < repetitions; ++rep) {
    progress << "[bench engine] " << c.name << " (" << v.grid.dims[0] << "x" << v.grid.dims[1] << "x"
             << v.grid.dims[2] << "): repetition " << rep + 1 << "/" << repetitions << "\n"
             << std::flush;
    if (chain) {
      // The standalone set right beside the chain (the same moment's load), before it in odd
      // repetitions and after it in even ones (neither order favoured).
      if (standalone && rep % 2) standalone->run();
      const auto t0 = Clock::now();
      const engine::ChainOutput g = chain->run(v);
      gpu_wall.push_back(ms_since(t0));
      for (std::size_t i = 0; i < np && i < g.passes.size(); ++i)
        gpu_ms[i].push_back(g.passes[i].ms >= 0 ? g.passes[i].ms : kNaN);
      if (standalone) chain_pair_ms.push_back(passes_ms(g, np));
      if (standalone && rep % 2 == 0) standalone->run();
      if (standalone) extra_pairs(*chain, *standalone, v, np, rep, chain_pair_ms);
      if (floors) try {
          floors->sample(v);
        } catch (const std::exception& e) {
          progress << "[bench engine] copy floor: " << e.what() << "\n";
          floors.reset();
        }
    }
    if (legacy) {
      const auto t0 = Clock::now();
      const engine::ChainOutput g = legacy->run(v);
      legacy_wall.push_back(ms_since(t0));
      for (std::size_t i = 0; i < np && i < g.passes.size(); ++i)
        legacy_ms[i].push_back(g.passes[i].ms >= 0 ? g.passes[i].ms : kNaN);
    }
    if (run_peers)
      for (int t = 0; t < 2; ++t) peer_runs[t].push_back(run_peers_once(v, sigma_mm, t + 1));
    {
      const auto t0 = Clock::now();
      const engine::ChainOutput h = engine::run_chain_cpu(v, dense);
      cpu_wall.push_back(ms_since(t0));
      for (std::size_t i = 0; i < np && i < h.passes.size(); ++i) cpu_ms[i].push_back(h.passes[i].ms);
      if (r.cpu_backend_threads > 1) {
        const auto t1 = Clock::now();
        const engine::ChainOutput m = engine::run_chain_cpu(v, dense, r.cpu_backend_threads);
        cpu_mt_wall.push_back(ms_since(t1));
        // Bit for bit the reference: the samples (every voxel) and the brick ranges.
        const bool same = h.samples && m.samples && h.bricks && m.bricks &&
                          h.samples->samples.size() == m.samples->samples.size() &&
                          std::memcmp(h.samples->samples.data(), m.samples->samples.data(),
                                      h.samples->samples.size() * sizeof(core::Sample)) == 0 &&
                          h.bricks->min == m.bricks->min && h.bricks->max == m.bricks->max;
        r.cpu_backend_same_bits = (rep == 0 || r.cpu_backend_same_bits) && same;
      }
      if (standalone && rep == 0) standalone->check(h);  // the outputs of its run beside the chain's
    }
    for (std::size_t k = 0; k < ni; ++k) {
      guarded(sg[k], [&] { sg[k].add(schain->run(v, c.isos[k], bg[k])); });
      guarded(sb[k], [&] { sb[k].add(sbrick->run(v, c.isos[k], bg[k])); });
      guarded(sd[k], [&] { sd[k].add(sdense->run(v, c.isos[k], bg[k])); });
      guarded(sc[k], [&] {
        sc[k].add(engine::run_sparse_cpu(v, sparse, c.isos[k], bg[k], core::SampleFormat::kFp32, false, 1,
                                         cpu_pools));
      });
      if (r.cpu_backend_threads > 1)
        guarded(smt[k], [&] {
          smt[k].add(engine::run_sparse_cpu(v, sparse, c.isos[k], bg[k], core::SampleFormat::kFp32, false,
                                            r.cpu_backend_threads, cpu_mt_pools));
        });
    }
  }
  r.gpu_available = chain != nullptr;
  if (schain) {
    r.sparse_recycled_pools = schain->recycled_pools();
    r.sparse_retained_bytes = schain->retained_pool_bytes();
    r.sparse_runs = std::uint64_t(ni) * std::uint64_t(repetitions + 1);  // + the warm-up run per isovalue
  }
  for (std::size_t i = 0; i < np; ++i) {
    PassRow p;
    p.label = dense[i].label();
    p.min_bytes = pass_min_bytes(dense[i].kind, r.voxels, r.bricks);
    p.gpu_ms = median(gpu_ms[i]);
    p.cpu_ms = median(cpu_ms[i]);
    p.legacy_gpu_ms = median(legacy_ms[i]);
    r.passes.push_back(p);
  }
  r.legacy_gpu_wall_ms = median(legacy_wall);
  if (standalone) r.standalone = standalone->figures();
  r.chain_pair_ms = chain_pair_ms;
  if (floors) {
    r.copy_floor_ms = floors->median_of(FloorTraffic::Samples);
    std::tie(r.chain_floor_ms, r.chain_passes_floor_ms) = chain_floor_ms(*floors, dense);
  }
  if (run_peers)
    for (int t = 0; t < 2; ++t) {
      PeerRow pr;
      pr.threads = t + 1;
      std::vector<double> a, b, c2, d2, e;
      for (const PeerTimes& x : peer_runs[t]) {
        a.push_back(x.itk_gaussian_ms);
        b.push_back(x.itk_gradient_ms);
        c2.push_back(x.itk_pack_ms);
        d2.push_back(x.vdb_from_dense_ms);
        e.push_back(x.vdb_gradient_ms);
        if (pr.why.empty() && !(x.itk_why + x.vdb_why).empty()) pr.why = x.itk_why + " " + x.vdb_why;
      }
      pr.itk_gaussian_ms = median(a);
      pr.itk_gradient_ms = median(b);
      pr.itk_pack_ms = median(c2);
      pr.vdb_from_dense_ms = median(d2);
      pr.vdb_gradient_ms = median(e);
      r.peers.push_back(pr);
    }
  r.dense_gpu_wall_ms = median(gpu_wall);
  r.dense_cpu_wall_ms = median(cpu_wall);
  r.dense_cpu_mt_wall_ms = median(cpu_mt_wall);

  for (std::size_t k = 0; k < ni; ++k) {
    IsoResult ir;
    ir.iso = c.isos[k];
    ir.gpu = sg[k].cell();
    ir.gpu_per_brick = sb[k].cell();
    ir.gpu_dense = sd[k].cell();
    ir.cpu_mt = smt[k].cell();
    ir.cpu = sc[k].cell();
    if (ir.gpu.available && ir.cpu.available) {
      const auto &a = ir.gpu.stats, &b = ir.cpu.stats;
      if (a.bricks_total == b.bricks_total && a.candidates == b.candidates && a.active == b.active &&
          a.snapshot_bytes == b.snapshot_bytes)
        ir.gpu_cpu_counts = "same";
      else {
        std::ostringstream o;
        o << "differ: GPU " << a.candidates << "/" << a.active << "/" << a.snapshot_bytes << " B, CPU " << b.candidates
          << "/" << b.active << "/" << b.snapshot_bytes << " B (candidates/active/bytes)";
        ir.gpu_cpu_counts = o.str();
      }
    }
    for (const auto f : {core::SampleFormat::kFp32, core::SampleFormat::kFp16, core::SampleFormat::kUnorm16}) {
      FormatBytes fb;
      fb.format = f;
      auto take = [&](const engine::SparseStats& s, const char* eng) {
        fb.available = true;
        fb.engine = eng;
        fb.snapshot_bytes = s.snapshot_bytes;
        fb.dense_fp32_bytes = s.dense_fp32_bytes;
      };
      if (f == core::SampleFormat::kFp32 && (ir.gpu.available || ir.cpu.available)) {
        take(ir.gpu.available ? ir.gpu.stats : ir.cpu.stats, ir.gpu.available ? "GPU" : "CPU reference");
      } else {
        std::string why;
        if (ir.gpu.available) {
          try {
            take(schain->run(v, c.isos[k], bg[k], f).stats, "GPU");
          } catch (const std::exception& e) {
            why = std::string("GPU: ") + e.what();
          }
        }
        if (!fb.available && ir.cpu.available) {
          try {
            take(engine::run_sparse_cpu(v, sparse, c.isos[k], bg[k], f).stats, "CPU reference");
          } catch (const std::exception& e) {
            why += (why.empty() ? "" : "; ") + std::string("CPU: ") + e.what();
          }
        }
        if (!fb.available) fb.why = why.empty() ? "sparse: not available (" + ir.gpu.why + ")" : why;
      }
      ir.formats.push_back(fb);
    }
    r.isos.push_back(ir);
  }
  finish_case(r);
  return r;
}

void finish_case(CaseResult& r) {
  auto derive = [&](PassRow& p) {
    p.gpu_gbps = gb_per_s(double(p.min_bytes), p.gpu_ms);
    p.cpu_gbps = gb_per_s(double(p.min_bytes), p.cpu_ms);
    p.gpu_of_memcpy = ratio(p.gpu_gbps, r.memcpy_gbps);
    p.cpu_of_memcpy = ratio(p.cpu_gbps, r.memcpy_gbps);
    p.gpu_over_cpu = ratio(p.gpu_ms, p.cpu_ms);
    p.legacy_over_gpu = ratio(p.legacy_gpu_ms, p.gpu_ms);
  };
  PassRow sum;
  sum.label = "sum of passes";
  sum.gpu_ms = sum.cpu_ms = 0;
  for (PassRow& p : r.passes) {
    derive(p);
    sum.min_bytes += p.min_bytes;
    sum.gpu_ms += p.gpu_ms;  // NaN if any pass has no time
    sum.cpu_ms += p.cpu_ms;
  }
  sum.legacy_gpu_ms = 0;
  for (const PassRow& p : r.passes) sum.legacy_gpu_ms += p.legacy_gpu_ms;
  if (r.passes.empty()) sum.gpu_ms = sum.cpu_ms = sum.legacy_gpu_ms = kNaN;
  derive(sum);
  r.sum = sum;
  r.fastest_peer_chain_ms = kNaN;
  r.fastest_peer_chain.clear();
  for (PeerRow& pr : r.peers) {
    pr.itk_chain_ms = pr.itk_gaussian_ms + pr.itk_gradient_ms + pr.itk_pack_ms;
    pr.itk_vdb_chain_ms = pr.itk_gaussian_ms + pr.vdb_from_dense_ms + pr.vdb_gradient_ms;
    const std::string th = std::to_string(pr.threads) + " thread" + (pr.threads > 1 ? "s" : "");
    for (const auto& [ms, name] : {std::pair{pr.itk_chain_ms, "ITK Gaussian + ITK gradient + packing, " + th},
                                   std::pair{pr.itk_vdb_chain_ms, "ITK Gaussian + OpenVDB copyFromDense + gradient, " + th}})
      if (std::isfinite(ms) && !(ms >= r.fastest_peer_chain_ms)) {
        r.fastest_peer_chain_ms = ms;
        r.fastest_peer_chain = name;
      }
  }
  r.chain_over_peer = ratio(r.sum.gpu_ms, r.fastest_peer_chain_ms);
  r.memcpy_ms = std::isfinite(r.memcpy_gbps) && r.memcpy_gbps > 0 ? double(r.sum.min_bytes) / (r.memcpy_gbps * 1e9) * 1e3
                                                                  : kNaN;
  r.chain_over_memcpy = ratio(r.sum.gpu_ms, r.memcpy_ms);
  const double grad_bytes = double(pass_min_bytes(engine::PassKind::Gradient, r.voxels, r.bricks));
  r.copy_floor_memcpy_ms = std::isfinite(r.memcpy_gbps) && r.memcpy_gbps > 0 ? grad_bytes / (r.memcpy_gbps * 1e9) * 1e3
                                                                             : kNaN;
  r.floor_over_memcpy = ratio(r.copy_floor_ms, r.copy_floor_memcpy_ms);
  r.chain_floor_over_memcpy = ratio(r.chain_floor_ms, r.memcpy_ms);
  r.chain_over_floor = ratio(r.sum.gpu_ms, r.chain_floor_ms);
  r.chain_over_passes_floor = ratio(r.sum.gpu_ms, r.chain_passes_floor_ms);
  r.chain_over_standalone = r.standalone.why.empty() ? paired_ratio(r.chain_pair_ms, r.standalone.set_ms_per_run) : kNaN;
  r.gradient_over_floor = kNaN;
  for (const PassRow& p : r.passes)
    if (p.label == "gradient") r.gradient_over_floor = ratio(p.gpu_ms, r.copy_floor_ms);
  r.dense_gpu_over_cpu_wall = ratio(r.dense_gpu_wall_ms, r.dense_cpu_wall_ms);
  for (IsoResult& ir : r.isos) {
    const SparseCell* s = ir.gpu.available ? &ir.gpu : ir.cpu.available ? &ir.cpu : nullptr;
    if (s && s->stats.bricks_total > 0) {
      ir.active_percent = 100.0 * double(s->stats.active) / double(s->stats.bricks_total);
      ir.candidate_percent = 100.0 * double(s->stats.candidates) / double(s->stats.bricks_total);
    }
    for (FormatBytes& f : ir.formats)
      f.percent = f.available && f.dense_fp32_bytes > 0 ? 100.0 * double(f.snapshot_bytes) / double(f.dense_fp32_bytes)
                                                        : kNaN;
    ir.sparse_gpu_over_dense_cpu = ratio(ir.gpu.total_ms, r.dense_cpu_wall_ms);
    ir.sparse_cpu_over_dense_cpu = ratio(ir.cpu.total_ms, r.dense_cpu_wall_ms);
    ir.sparse_gpu_over_dense_gpu = ratio(ir.gpu.total_ms, r.dense_gpu_wall_ms);
  }
}

// ---------------------------------------------------------------------------------------
// 512^3 end to end

namespace {
/// The first servo ticks on the published snapshot `field` of the noisy sphere (radius
/// 0.375 n voxels about the grid centre, inside above 0): the snapshot handed over as the
/// engine hands it to the servo (servo::TripleBuffer), then HRI (robust, n = 5) with the HIP
/// one voxel outside the surface (the first tick: free space, samples read next to the
/// surface), then 999 ticks pressing it in to one voxel inside (contact, planes made).
/// Writes publish_ms, first_tick_us, ticks_median_us, max_force_n.
void first_ticks(core::SampleField field, int n, std::ostream& out) {
  auto t0 = Clock::now();
  servo::TripleBuffer<core::SampleField> tb;
  tb.publish(std::make_shared<const core::SampleField>(std::move(field)));
  const core::SampleField* snap = tb.acquire();
  out << "publish_ms=" << ms_since(t0) << "\n";
  servo::HriParams hp;
  hp.tau = 0.0;
  hp.inside = core::InsideIs::kAbove;
  servo::HriRenderer hri(hp);
  const double h = snap->grid.spacing_m.x, r = 0.375 * n * h;
  const core::Vec3 c = snap->grid.centre_m();
  t0 = Clock::now();
  servo::HriTick tick = hri.tick(core::FieldView(*snap), c + core::Vec3{r + h, 0.0, 0.0});
  out << "first_tick_us=" << ms_since(t0) * 1e3 << "\n";
  std::vector<double> us;
  double max_force = core::norm(tick.force_n);
  for (int i = 1; i < 1000; ++i) {
    const core::Vec3 hip = c + core::Vec3{r + h - 2.0 * h * double(i) / 999.0, 0.0, 0.0};
    const auto t1 = Clock::now();
    tick = hri.tick(core::FieldView(*snap), hip);
    us.push_back(ms_since(t1) * 1e3);
    max_force = std::max(max_force, core::norm(tick.force_n));
  }
  out << "ticks_median_us=" << median(us) << "\n" << "max_force_n=" << max_force << "\n";
}
}  // namespace

int run_big_child(int n, const std::string& device, std::ostream& out, std::ostream& progress) {
  out << "dim=" << n << "\n";
  progress << "[bench engine] " << n << "^3: making the noisy sphere\n" << std::flush;
  auto t0 = Clock::now();
  const engine::Volume v = make_noisy_sphere(n, 1e-3);
  out << "make_ms=" << ms_since(t0) << "\n";
  const core::Isosurface iso{0.0, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(v.min_value, v.max_value));
  const auto list = sparse_list(false);
  std::string note;
  bool done = false;
  engine::SparseOutput o;
  try {
    t0 = Clock::now();
    engine::ContextOptions co;
    co.device = device;
    auto ctx = engine::VulkanContext::create(co);
    if (!ctx) throw std::runtime_error("Vulkan: " + ctx.error);
    auto chain = engine::SparseChain::create(**ctx.value, list);
    if (!chain) throw std::runtime_error(chain.error);
    out << "setup_ms=" << ms_since(t0) << "\n" << "device=" << (*ctx.value)->info().name << "\n";
    progress << "[bench engine] " << n << "^3: sparse GPU chain\n" << std::flush;
    t0 = Clock::now();
    o = (*chain.value)->run(v, iso, bg);
    out << "step_ms=" << ms_since(t0) << "\n" << "engine=sparse GPU\n";
    done = true;
  } catch (const std::exception& e) {
    note = std::string("sparse GPU: not available (") + e.what() + ")";
  }
  if (!done) {
    try {
      progress << "[bench engine] " << n << "^3: sparse CPU reference\n" << std::flush;
      t0 = Clock::now();
      o = engine::run_sparse_cpu(v, list, iso, bg);
      out << "step_ms=" << ms_since(t0) << "\n" << "engine=sparse CPU reference\n";
      done = true;
    } catch (const std::exception& e) {
      note += std::string("; sparse CPU: not available (") + e.what() + ")";
    }
  }
  if (done) {
    const engine::SparseStats& st = o.stats;
    out << "snapshot_bytes=" << st.snapshot_bytes << "\n" << "dense_fp32_bytes=" << st.dense_fp32_bytes << "\n"
        << "bricks_total=" << st.bricks_total << "\n" << "candidates=" << st.candidates << "\n"
        << "active=" << st.active << "\n" << "stages=" << o.passes.size() << "\n";
    for (std::size_t i = 0; i < o.passes.size(); ++i)
      out << "stage" << i << "_ms=" << o.passes[i].ms << "\n" << "stage" << i << "_label=" << o.passes[i].label << "\n";
    progress << "[bench engine] " << n << "^3: first servo ticks\n" << std::flush;
    first_ticks(std::move(o.field), n, out);
  }
  out << "note=" << note << "\n" << "vm_hwm_bytes=" << self_peak_rss_bytes() << "\n" << std::flush;
  return done ? 0 : 3;
}

namespace {
BigResult run_big(const BenchEngineOptions& o, std::ostream& progress) {
  BigResult b;
  b.dim = o.big_dim;
  std::vector<std::string> argv = {o.self_exe, "bench", "engine", "--big-child", std::to_string(o.big_dim)};
  if (!o.device.empty()) argv.insert(argv.end(), {"--device", o.device});
  progress << "[bench engine] " << o.big_dim << "^3 end to end in a child process (" << o.self_exe << ")\n"
           << std::flush;
  b.child = run_child_exec(argv);
  b.kv = parse_key_values(b.child.out);
  if (!b.child.started) b.note = b.child.error;
  else if (b.child.signal) b.note = "child killed by signal " + std::to_string(b.child.signal);
  else if (b.child.exit_code != 0) b.note = "child exit code " + std::to_string(b.child.exit_code);
  if (b.kv.count("note") && !b.kv["note"].empty()) b.note += (b.note.empty() ? "" : "; ") + b.kv["note"];
  return b;
}

// ---------------------------------------------------------------------------------------
// Report

std::string num(double x, int prec = 2) {
  if (!std::isfinite(x)) return "n/a";
  std::ostringstream o;
  o << std::fixed << std::setprecision(prec) << x;
  return o.str();
}
std::string mib(std::uint64_t b) { return num(double(b) / (1024.0 * 1024.0), 2); }
std::string tau_text(const core::Isosurface& iso) {
  std::ostringstream o;
  o << (iso.tau > 0 ? "+" : "") << iso.tau;
  return o.str();
}

// One CSV (long form: one figure per row).
struct Csv {
  std::ostringstream s;
  Csv() { s << "table,case,tau,row,column,value,unit,device\n"; }
  static std::string q(const std::string& x) {
    if (x.find_first_of(",\"\n") == std::string::npos) return x;
    std::string r = "\"";
    for (char c : x) r += c == '"' ? std::string("\"\"") : std::string(1, c);
    return r + "\"";
  }
  void row(const std::string& table, const std::string& cs, const std::string& tau, const std::string& r,
           const std::string& col, const std::string& value, const std::string& unit, const std::string& dev) {
    s << q(table) << ',' << q(cs) << ',' << q(tau) << ',' << q(r) << ',' << q(col) << ',' << q(value) << ','
      << q(unit) << ',' << q(dev) << '\n';
  }
};
std::string csv_num(double x) {
  if (!std::isfinite(x)) return "";
  std::ostringstream o;
  o << std::setprecision(9) << x;
  return o.str();
}


std::uint64_t mem_total_bytes() {
  std::ifstream f("/proc/meminfo");
  std::string k;
  std::uint64_t v = 0;
  std::string unit;
  while (f >> k >> v >> unit)
    if (k == "MemTotal:") return v * 1024;
  return 0;
}


std::string resolve_data(const std::string& rel) {
  if (fs::exists(rel)) return rel;
  return (fs::path(ISOTOUCH_SOURCE_DIR) / rel).string();
}

struct Devices {
  std::string gpu, cpu;
};

void print_dense(const std::vector<CaseResult>& res, const Devices& d, std::ostream& out, Csv& csv) {
  out << "\n## Dense passes: time and effective bandwidth\n\n"
      << "| case | pass | min bytes [MiB] | dense GPU [ms] | legacy shaders [ms] | legacy / current | dense CPU [ms] "
         "| GPU / CPU | GPU [GB/s] | GPU / memcpy | CPU [GB/s] | CPU / memcpy |\n"
      << "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const auto& r : res) {
    auto line = [&](const PassRow& p) {
      const std::string g = r.gpu_available ? num(p.gpu_ms) : "n/a (" + r.gpu_why + ")";
      out << "| " << r.name << " | " << p.label << " | "
          << mib(p.min_bytes) << " | " << g << " | "
          << num(p.legacy_gpu_ms) << " | " << num(p.legacy_over_gpu) << " | " << num(p.cpu_ms)
          << " | " << num(p.gpu_over_cpu, 3) << " | " << num(p.gpu_gbps) << " | " << num(p.gpu_of_memcpy, 3) << " | "
          << num(p.cpu_gbps) << " | " << num(p.cpu_of_memcpy, 3) << " |\n";
      const std::string t = "dense";
      csv.row(t, r.name, "", p.label, "min_bytes", std::to_string(p.min_bytes), "B", "");
      csv.row(t, r.name, "", p.label, "dense_gpu_ms", csv_num(p.gpu_ms), "ms", d.gpu);
      csv.row(t, r.name, "", p.label, "dense_cpu_ms", csv_num(p.cpu_ms), "ms", d.cpu);
      csv.row(t, r.name, "", p.label, "legacy_gpu_ms", csv_num(p.legacy_gpu_ms), "ms", d.gpu);
      csv.row(t, r.name, "", p.label, "legacy_over_gpu", csv_num(p.legacy_over_gpu), "", "");
      csv.row(t, r.name, "", p.label, "gpu_over_cpu", csv_num(p.gpu_over_cpu), "", "");
      csv.row(t, r.name, "", p.label, "gpu_gbps", csv_num(p.gpu_gbps), "GB/s", d.gpu);
      csv.row(t, r.name, "", p.label, "gpu_of_memcpy", csv_num(p.gpu_of_memcpy), "", d.gpu);
      csv.row(t, r.name, "", p.label, "cpu_gbps", csv_num(p.cpu_gbps), "GB/s", d.cpu);
      csv.row(t, r.name, "", p.label, "cpu_of_memcpy", csv_num(p.cpu_of_memcpy), "", d.cpu);
    };
    for (const auto& p : r.passes) line(p);
    line(r.sum);
    out << "| " << r.name << " | end to end (wall) | | " << num(r.dense_gpu_wall_ms) << " | "
        << num(r.legacy_gpu_wall_ms) << " | " << num(ratio(r.legacy_gpu_wall_ms, r.dense_gpu_wall_ms)) << " | "
        << num(r.dense_cpu_wall_ms) << " | " << num(r.dense_gpu_over_cpu_wall, 3) << " | | | | |\n";
    csv.row("dense", r.name, "", "end to end (wall)", "legacy_gpu_ms", csv_num(r.legacy_gpu_wall_ms), "ms", d.gpu);
    csv.row("dense", r.name, "", "end to end (wall)", "dense_gpu_ms", csv_num(r.dense_gpu_wall_ms), "ms", d.gpu);
    csv.row("dense", r.name, "", "end to end (wall)", "dense_cpu_ms", csv_num(r.dense_cpu_wall_ms), "ms", d.cpu);
    csv.row("dense", r.name, "", "end to end (wall)", "gpu_over_cpu", csv_num(r.dense_gpu_over_cpu_wall), "", "");
  }
}

void print_peers(const std::vector<CaseResult>& res, const Devices& d, std::ostream& out, Csv& csv) {
  out << "\n## Peers on the same cores (wall, medians) against the dense GPU chain\n\n"
      << "| case | threads | ITK Gaussian | ITK gradient | packing | ITK chain | OpenVDB copyFromDense | OpenVDB "
         "gradient | ITK Gaussian + OpenVDB chain | note |\n"
      << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
  for (const auto& r : res) {
    for (const auto& p : r.peers) {
      out << "| " << r.name << " | " << p.threads << " | " << num(p.itk_gaussian_ms) << " | " << num(p.itk_gradient_ms)
          << " | " << num(p.itk_pack_ms) << " | " << num(p.itk_chain_ms) << " | " << num(p.vdb_from_dense_ms) << " | "
          << num(p.vdb_gradient_ms) << " | " << num(p.itk_vdb_chain_ms) << " | " << p.why << " |\n";
      const std::string th = std::to_string(p.threads);
      csv.row("peers", r.name, "", "threads " + th, "itk_gaussian_ms", csv_num(p.itk_gaussian_ms), "ms", d.cpu);
      csv.row("peers", r.name, "", "threads " + th, "itk_gradient_ms", csv_num(p.itk_gradient_ms), "ms", d.cpu);
      csv.row("peers", r.name, "", "threads " + th, "itk_chain_ms", csv_num(p.itk_chain_ms), "ms", d.cpu);
      csv.row("peers", r.name, "", "threads " + th, "vdb_from_dense_ms", csv_num(p.vdb_from_dense_ms), "ms", d.cpu);
      csv.row("peers", r.name, "", "threads " + th, "vdb_gradient_ms", csv_num(p.vdb_gradient_ms), "ms", d.cpu);
      csv.row("peers", r.name, "", "threads " + th, "itk_vdb_chain_ms", csv_num(p.itk_vdb_chain_ms), "ms", d.cpu);
    }
  }
  out << "\n| case | dense GPU chain, device [ms] | fastest peer chain [ms] | which | chain / peer | memcpy of the "
         "chain's min bytes [ms] | chain / memcpy |\n|---|---:|---:|---|---:|---:|---:|\n";
  for (const auto& r : res) {
    out << "| " << r.name << " | " << num(r.sum.gpu_ms) << " | " << num(r.fastest_peer_chain_ms) << " | "
        << (r.fastest_peer_chain.empty() ? "n/a" : r.fastest_peer_chain) << " | " << num(r.chain_over_peer, 3) << " | "
        << num(r.memcpy_ms) << " | " << num(r.chain_over_memcpy, 2) << " |\n";
    csv.row("peers", r.name, "", "", "fastest_peer_chain_ms", csv_num(r.fastest_peer_chain_ms), "ms", d.cpu);
    csv.row("peers", r.name, "", "", "chain_over_peer", csv_num(r.chain_over_peer), "", "");
    csv.row("peers", r.name, "", "", "memcpy_ms", csv_num(r.memcpy_ms), "ms", d.cpu);
    csv.row("peers", r.name, "", "", "chain_over_memcpy", csv_num(r.chain_over_memcpy), "", "");
  }
  out << "\nThe device's floor for the gradient's bytes (read 4 B, write a 16 B sample per voxel): copy_x4.comp, "
         "the gradient pass's texel loads and vec4 stores without arithmetic, median device time; memcpy of the "
         "same bytes.\n\n| case | copy floor [ms] | memcpy of the same bytes [ms] | floor / memcpy | gradient pass "
         "[ms] | gradient / floor |\n|---|---:|---:|---:|---:|---:|\n";
  for (const auto& r : res) {
    double grad = kNaN;
    for (const PassRow& p : r.passes)
      if (p.label == "gradient") grad = p.gpu_ms;
    out << "| " << r.name << " | " << num(r.copy_floor_ms) << " | " << num(r.copy_floor_memcpy_ms) << " | "
        << num(r.floor_over_memcpy) << " | " << num(grad) << " | " << num(r.gradient_over_floor) << " |\n";
    csv.row("floor", r.name, "", "copy_x4", "copy_floor_ms", csv_num(r.copy_floor_ms), "ms", d.gpu);
    csv.row("floor", r.name, "", "copy_x4", "floor_over_memcpy", csv_num(r.floor_over_memcpy), "", "");
    csv.row("floor", r.name, "", "copy_x4", "gradient_over_floor", csv_num(r.gradient_over_floor), "", "");
  }
  out << "\nThe device's floor for the whole dense chain's bytes: copy_x4.comp once per pass with that pass's "
         "loads and stores and no arithmetic (a filter reads 4 B and writes 4 B per voxel, the gradient 4 B and a "
         "16 B sample, brick min/max reads 4 B), median device times summed; memcpy of the same bytes.\n\n| case "
         "| chain floor [ms] | memcpy of the chain's bytes [ms] | floor / memcpy | dense chain [ms] | chain / floor "
         "|\n|---|---:|---:|---:|---:|---:|\n";
  for (const auto& r : res) {
    out << "| " << r.name << " | " << num(r.chain_floor_ms) << " | " << num(r.memcpy_ms) << " | "
        << num(r.chain_floor_over_memcpy) << " | " << num(r.sum.gpu_ms) << " | " << num(r.chain_over_floor) << " |\n";
    csv.row("floor", r.name, "", "copy_x4 chain", "chain_floor_ms", csv_num(r.chain_floor_ms), "ms", d.gpu);
    csv.row("floor", r.name, "", "copy_x4 chain", "chain_floor_over_memcpy", csv_num(r.chain_floor_over_memcpy), "", "");
    csv.row("floor", r.name, "", "copy_x4 chain", "chain_over_floor", csv_num(r.chain_over_floor), "", "");
  }
}

/// How many chain/set pairs each case counted of those it made, e.g. "head 10 of 21 pairs".
std::string pairs_text(const std::vector<CaseResult>& res) {
  std::string t;
  for (const auto& r : res) {
    if (!r.standalone.why.empty()) continue;
    std::size_t counted = 0;
    for (std::size_t i = 0; i < r.chain_pair_ms.size() && i < r.standalone.set_ms_per_run.size(); ++i)
      counted += std::isfinite(ratio(r.chain_pair_ms[i], r.standalone.set_ms_per_run[i])) ? 1 : 0;
    t += (t.empty() ? "" : ", ") + r.name + " " + std::to_string(counted) + " of " + std::to_string(r.chain_pair_ms.size()) +
         " pairs";
  }
  return t.empty() ? "no pairs" : t;
}

/// The dense chain's passes beside the standalone set's (bench_reference.h), and the chain
/// against the set and against the device's copy floor for its bytes.
void print_standalone(const std::vector<CaseResult>& res, const Devices& d, std::ostream& out, Csv& csv) {
  out << "\n## The dense chain beside the standalone pass set (same run, device time, medians)\n\n"
      << "The same work as standalone passes in the fastest forms measured on lavapipe (the study's "
         "vec4-per-invocation, texel-fetch shaders ported into shaders/: gauss_axis_x4, "
         "gradient_whole_x4; brick min/max: the faster "
         "of two standalone forms), each output compared bit for bit with the CPU chain's. CPU: "
      << d.cpu << ".\n\n| case | standalone pass | standalone [ms] | bits vs CPU | dense chain's pass | chain [ms] "
         "|\n|---|---|---:|---|---|---:|\n";
  for (const auto& r : res) {
    if (!r.standalone.why.empty()) {
      out << "| " << r.name << " | not run: " << r.standalone.why << " | | | | |\n";
      continue;
    }
    for (std::size_t i = 0; i < r.standalone.rows.size(); ++i) {
      const StandaloneRow& s = r.standalone.rows[i];
      const PassRow* p = &r.passes[std::min<std::size_t>(i, r.passes.size() - 1)];  // both brick min/max forms: the last
      out << "| " << r.name << " | " << s.label << " | " << num(s.ms >= 0 ? s.ms : kNaN) << " | "
          << (s.same_bits ? "same" : "DIFFER") << " | " << p->label << " | " << num(p->gpu_ms) << " |\n";
      csv.row("standalone", r.name, "", s.label, "ms", csv_num(s.ms >= 0 ? s.ms : kNaN), "ms", d.gpu);
      csv.row("standalone", r.name, "", s.label, "same_bits", s.same_bits ? "1" : "0", "", "");
    }
  }
  out << "\nchain / set: the median over the runs of the chain and the set made back to back (" << pairs_text(res)
      << ") of the chain's device time over the set's in the same pair, so both see the same moment's load (pairs whose "
         "set ran its faster brick min/max form untimed skipped: the two forms take turns right after the gradient, as "
         "the chain's runs, the other one before it); "
         "the two [ms] columns are medians over all runs. chain floor: copy_x4 once per pass with its loads and "
         "stores (the chain's bytes); passes floor: "
         "copy_x4 once per pass over the field as the chain runs them (a Gaussian's x, y and z).\n\n"
         "| case | dense chain [ms] | best standalone set [ms] | chain / set | chain floor [ms] | chain / floor | "
         "passes floor [ms] | chain / passes floor | CPU |\n|---|---:|---:|---:|---:|---:|---:|---:|---|\n";
  for (const auto& r : res) {
    const double set = r.standalone.why.empty() ? r.standalone.best_set_ms : kNaN;
    out << "| " << r.name << " | " << num(r.sum.gpu_ms) << " | " << num(set) << " | " << num(r.chain_over_standalone, 3)
        << " | " << num(r.chain_floor_ms) << " | " << num(r.chain_over_floor, 3) << " | "
        << num(r.chain_passes_floor_ms) << " | " << num(r.chain_over_passes_floor, 3) << " | " << d.cpu << " |\n";
    csv.row("standalone", r.name, "", "passes floor", "ms", csv_num(r.chain_passes_floor_ms), "ms", d.gpu);
    csv.row("standalone", r.name, "", "best set", "ms", csv_num(set), "ms", d.gpu);
    csv.row("standalone", r.name, "", "best set", "chain_over_standalone", csv_num(r.chain_over_standalone), "", "");
  }
}

std::string sparse_cell(const SparseCell& c, double v, int prec = 2) {
  return c.available ? num(v, prec) : "sparse: not available (" + c.why + ")";
}

void print_cpu_backend(const std::vector<CaseResult>& res, const Devices& d, std::ostream& out, Csv& csv) {
  out << "\n## CPU backend (where no Vulkan device exists): the dense chain's rows split among threads\n\n"
      << "| case | threads | dense CPU chain [ms] | one-thread reference [ms] | speed-up | bits |\n"
      << "|---|---:|---:|---:|---:|---|\n";
  for (const auto& r : res) {
    if (r.cpu_backend_threads < 2) {
      out << "| " << r.name << " | 1 | not run: one hardware thread | | | |\n";
      continue;
    }
    out << "| " << r.name << " | " << r.cpu_backend_threads << " | " << num(r.dense_cpu_mt_wall_ms) << " | "
        << num(r.dense_cpu_wall_ms) << " | " << num(ratio(r.dense_cpu_wall_ms, r.dense_cpu_mt_wall_ms)) << " | "
        << (r.cpu_backend_same_bits ? "same as the reference (samples, brick ranges)" : "DIFFER from the reference")
        << " |\n";
    csv.row("cpu_backend", r.name, "", std::to_string(r.cpu_backend_threads) + " threads", "dense_cpu_ms",
            csv_num(r.dense_cpu_mt_wall_ms), "ms", d.cpu);
  }
  out << "\n| case | tau | threads | sparse CPU [ms] | one-thread sparse reference [ms] | speed-up | counts |\n"
      << "|---|---:|---:|---:|---:|---:|---|\n";
  for (const auto& r : res)
    for (const auto& ir : r.isos) {
      if (r.cpu_backend_threads < 2) continue;
      const bool same = ir.cpu_mt.available && ir.cpu.available &&
                        ir.cpu_mt.stats.candidates == ir.cpu.stats.candidates &&
                        ir.cpu_mt.stats.active == ir.cpu.stats.active &&
                        ir.cpu_mt.stats.snapshot_bytes == ir.cpu.stats.snapshot_bytes;
      out << "| " << r.name << " | " << tau_text(ir.iso) << " | " << r.cpu_backend_threads << " | "
          << sparse_cell(ir.cpu_mt, ir.cpu_mt.total_ms) << " | " << sparse_cell(ir.cpu, ir.cpu.total_ms) << " | "
          << num(ratio(ir.cpu.total_ms, ir.cpu_mt.total_ms)) << " | "
          << (same ? "same bricks and bytes as the reference" : "differ or not run") << " |\n";
      csv.row("cpu_backend", r.name, tau_text(ir.iso), std::to_string(r.cpu_backend_threads) + " threads",
              "sparse_cpu_ms", csv_num(ir.cpu_mt.total_ms), "ms", d.cpu);
    }
}

void print_sparse(const std::vector<CaseResult>& res, const Devices& d, std::ostream& out, Csv& csv) {
  out << "\n## Sparse: bricks and time (fp32 snapshot)\n\n"
      << "| case | tau | bricks | candidates | active | active % | sparse GPU [ms] | sparse CPU [ms] | dense GPU "
         "[ms] | dense CPU [ms] | sparse GPU / dense CPU | sparse CPU / dense CPU | sparse GPU / dense GPU | GPU vs "
         "CPU counts | sparse GPU, dense strategy [ms] | sparse GPU, per-brick kernel [ms] |\n"
      << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|\n";
  for (const auto& r : res)
    for (const auto& ir : r.isos) {
      const SparseCell& s = ir.gpu.available ? ir.gpu : ir.cpu;
      const bool have = s.available;
      const std::string na = "sparse: not available (" + ir.gpu.why + ")";
      const std::string tau = tau_text(ir.iso);
      out << "| " << r.name << " | " << tau << " | " << (have ? std::to_string(s.stats.bricks_total) : na) << " | "
          << (have ? std::to_string(s.stats.candidates) : na) << " | " << (have ? std::to_string(s.stats.active) : na)
          << " | " << num(ir.active_percent) << " | " << sparse_cell(ir.gpu, ir.gpu.total_ms) << " | "
          << sparse_cell(ir.cpu, ir.cpu.total_ms) << " | " << num(r.dense_gpu_wall_ms) << " | "
          << num(r.dense_cpu_wall_ms) << " | " << sparse_cell(ir.gpu, ir.sparse_gpu_over_dense_cpu, 3) << " | "
          << sparse_cell(ir.cpu, ir.sparse_cpu_over_dense_cpu, 3) << " | "
          << sparse_cell(ir.gpu, ir.sparse_gpu_over_dense_gpu, 3) << " | "
          << (ir.gpu_cpu_counts.empty() ? "n/a" : ir.gpu_cpu_counts) << " | "
          << sparse_cell(ir.gpu_dense, ir.gpu_dense.total_ms) << " | "
          << sparse_cell(ir.gpu_per_brick, ir.gpu_per_brick.total_ms) << " |\n";
      const std::string t = "sparse";
      if (have) {
        csv.row(t, r.name, tau, "", "bricks_total", std::to_string(s.stats.bricks_total), "", "");
        csv.row(t, r.name, tau, "", "candidates", std::to_string(s.stats.candidates), "", "");
        csv.row(t, r.name, tau, "", "active", std::to_string(s.stats.active), "", "");
      }
      csv.row(t, r.name, tau, "", "active_percent", csv_num(ir.active_percent), "%", "");
      csv.row(t, r.name, tau, "", "candidate_percent", csv_num(ir.candidate_percent), "%", "");
      csv.row(t, r.name, tau, "", "sparse_gpu_ms", csv_num(ir.gpu.total_ms), "ms", d.gpu);
      csv.row(t, r.name, tau, "", "sparse_cpu_ms", csv_num(ir.cpu.total_ms), "ms", d.cpu);
      csv.row(t, r.name, tau, "", "sparse_gpu_dense_strategy_ms", csv_num(ir.gpu_dense.total_ms), "ms", d.gpu);
      csv.row(t, r.name, tau, "", "sparse_gpu_per_brick_ms", csv_num(ir.gpu_per_brick.total_ms), "ms", d.gpu);
      csv.row(t, r.name, tau, "", "sparse_gpu_over_dense_cpu", csv_num(ir.sparse_gpu_over_dense_cpu), "", "");
      csv.row(t, r.name, tau, "", "sparse_cpu_over_dense_cpu", csv_num(ir.sparse_cpu_over_dense_cpu), "", "");
      csv.row(t, r.name, tau, "", "sparse_gpu_over_dense_gpu", csv_num(ir.sparse_gpu_over_dense_gpu), "", "");
    }
  for (const auto& r : res)
    if (r.sparse_runs)
      out << "\n" << r.name << ": the sparse GPU chain (lists) published into the retained pool buffer of a "
          << "snapshot already destroyed in " << r.sparse_recycled_pools << " of its " << r.sparse_runs
          << " runs (the rest into fresh pages); after the last run it retains " << mib(r.sparse_retained_bytes)
          << " MiB for no snapshot (counted in this process's RSS).\n";
  out << "\n### Sparse stages (medians)\n\n| case | tau | engine | stage | ms |\n|---|---:|---|---|---:|\n";
  for (const auto& r : res)
    for (const auto& ir : r.isos)
      for (const auto* c : {&ir.gpu, &ir.gpu_dense, &ir.cpu}) {
        const std::string eng = c == &ir.gpu ? "GPU (lists)" : c == &ir.gpu_dense ? "GPU (dense strategy)" : "CPU reference";
        if (!c->available) {
          out << "| " << r.name << " | " << tau_text(ir.iso) << " | " << eng << " | sparse: not available (" << c->why
              << ") | |\n";
          continue;
        }
        for (std::size_t i = 0; i < c->stage_ms.size(); ++i) {
          out << "| " << r.name << " | " << tau_text(ir.iso) << " | " << eng << " | " << c->stage_labels[i] << " | "
              << num(c->stage_ms[i]) << " |\n";
          csv.row("sparse_stages", r.name, tau_text(ir.iso), c->stage_labels[i], eng + "_ms", csv_num(c->stage_ms[i]),
                  "ms", c == &ir.cpu ? d.cpu : d.gpu);
        }
      }
}

void print_bytes(const std::vector<CaseResult>& res, std::ostream& out, Csv& csv) {
  out << "\n## Published snapshot bytes against dense fp32\n\n"
      << "| case | tau | format | from | snapshot [MiB] | dense fp32 [MiB] | sparse / dense % |\n"
      << "|---|---:|---|---|---:|---:|---:|\n";
  for (const auto& r : res)
    for (const auto& ir : r.isos)
      for (const auto& f : ir.formats) {
        const std::string tau = tau_text(ir.iso);
        if (!f.available) {
          out << "| " << r.name << " | " << tau << " | " << format_name(f.format) << " | " << f.why << " | | | |\n";
          continue;
        }
        out << "| " << r.name << " | " << tau << " | " << format_name(f.format) << " | " << f.engine << " | "
            << mib(f.snapshot_bytes) << " | " << mib(f.dense_fp32_bytes) << " | " << num(f.percent) << " |\n";
        csv.row("bytes", r.name, tau, format_name(f.format), "snapshot_bytes", std::to_string(f.snapshot_bytes), "B",
                f.engine);
        csv.row("bytes", r.name, tau, format_name(f.format), "dense_fp32_bytes", std::to_string(f.dense_fp32_bytes),
                "B", "");
        csv.row("bytes", r.name, tau, format_name(f.format), "percent", csv_num(f.percent), "%", "");
      }
}

/// The 512^3 run from the volume to the first servo tick, stage by stage (the child's
/// key=value report): making the volume (stands for loading it), Vulkan context and chain,
/// the chain's own stages, the hand-over to the servo, the first HRI tick.
void print_big_split(const BigResult& b, std::ostream& out, Csv& csv) {
  const auto& kv = b.kv;
  const auto val = [&](const std::string& k) {
    try {
      return kv.count(k) ? std::stod(kv.at(k)) : kNaN;
    } catch (...) {
      return kNaN;
    }
  };
  if (!kv.count("first_tick_us")) {
    out << "\nvolume to first servo tick: not measured (" << (b.note.empty() ? "no first tick" : b.note) << ")\n";
    return;
  }
  const std::string dim = std::to_string(b.dim) + "^3";
  const std::string dev = kv.count("device") ? kv.at("device") : "";
  out << "\n### " << dim << ": volume to first servo tick\n\n| step | ms |\n|---|---:|\n";
  const double make = val("make_ms"), setup = val("setup_ms"), step = val("step_ms"), pub = val("publish_ms"),
               tick = val("first_tick_us") / 1e3;
  out << "| make the volume (stands for loading it) | " << num(make) << " |\n"
      << "| Vulkan context + sparse chain created | " << num(setup) << " |\n"
      << "| sparse chain run (" << (kv.count("engine") ? kv.at("engine") : "n/a") << "), wall | " << num(step) << " |\n";
  const int stages = int(val("stages") >= 0 ? val("stages") : 0);
  double staged = 0;
  for (int i = 0; i < stages; ++i) {
    const std::string k = "stage" + std::to_string(i);
    const double ms = val(k + "_ms");
    staged += ms;
    out << "| - " << (kv.count(k + "_label") ? kv.at(k + "_label") : k) << " | " << num(ms) << " |\n";
    csv.row("big_split", dim, "0", kv.count(k + "_label") ? kv.at(k + "_label") : k, "ms", csv_num(ms), "ms", dev);
  }
  out << "| - rest of the run (buffers, recording, submit overhead) | " << num(step - staged) << " |\n"
      << "| snapshot handed to the servo (servo::TripleBuffer) | " << num(pub) << " |\n"
      << "| first HRI tick (HIP 1 voxel outside the surface) | " << num(tick, 4) << " |\n"
      << "| **volume to first servo tick** | **" << num(make + setup + step + pub + tick) << "** |\n"
      << "\nThe sparse chain's run includes lavapipe's first-use work (pipelines of this volume's sizes compiled "
         "at their first dispatch). Next 999 ticks on the same snapshot, pressing the HIP to 1 voxel inside: median "
      << num(val("ticks_median_us"), 3) << " us per tick, largest |F| " << num(val("max_force_n"), 3) << " N.\n";
  for (const auto& [k, v] : {std::pair{"publish_ms", pub}, std::pair{"first_tick_ms", tick},
                             std::pair{"volume_to_first_tick_ms", make + setup + step + pub + tick},
                             std::pair{"ticks_median_us", val("ticks_median_us")}})
    csv.row("big_split", dim, "0", "", k, csv_num(v), k == std::string("ticks_median_us") ? "us" : "ms", dev);
}

void print_big(const BigResult* b, std::ostream& out, Csv& csv, std::uint64_t mem_total) {
  out << "\n## 512^3 end to end (child process)\n\n";
  if (!b) {
    out << "not run (--quick without --big)\n";
    return;
  }
  auto kv = b->kv;
  const auto get = [&](const std::string& k) { return kv.count(k) ? kv.at(k) : std::string("n/a"); };
  out << "| volume | engine | device | step [ms] | setup [ms] | make volume [ms] | child wall [ms] | peak RSS "
         "wait4 [MiB] | child VmHWM [MiB] | MemTotal [MiB] | snapshot [MiB] | dense fp32 [MiB] | active / bricks | exit "
         "|\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
  const auto to_u = [&](const std::string& k) -> std::uint64_t {
    try {
      return kv.count(k) ? std::stoull(kv.at(k)) : 0;
    } catch (...) {
      return 0;
    }
  };
  const auto num_of = [&](const std::string& k) {
    try {
      return kv.count(k) ? num(std::stod(kv.at(k)), 0) : std::string("n/a");
    } catch (...) {
      return std::string("n/a");
    }
  };
  out << "| noisy sphere " << b->dim << "^3, 1 mm, tau 0 | " << get("engine") << " | " << get("device") << " | "
      << num_of("step_ms") << " | " << num_of("setup_ms") << " | " << num_of("make_ms") << " | " << num(b->child.wall_ms, 0)
      << " | " << mib(b->child.peak_rss_bytes) << " | " << mib(to_u("vm_hwm_bytes")) << " | " << mib(mem_total)
      << " | " << (kv.count("snapshot_bytes") ? mib(to_u("snapshot_bytes")) : "n/a") << " | "
      << (kv.count("dense_fp32_bytes") ? mib(to_u("dense_fp32_bytes")) : "n/a") << " | " << get("active") << " / "
      << get("bricks_total") << " | "
      << (b->child.signal ? "signal " + std::to_string(b->child.signal) : std::to_string(b->child.exit_code))
      << " |\n";
  if (!b->note.empty()) out << "\nnote: " << b->note << "\n";
  print_big_split(*b, out, csv);
  out << "\nPeak RSS (wait4 ru_maxrss) covers the whole child: making the volume, the Vulkan context, the chain and "
         "the published snapshot; Linux keeps in it the larger of the pre-exec (a fork of this small parent) and "
         "post-exec peaks. VmHWM is the child's own post-exec peak.\n";
  for (const auto& k : {"step_ms", "setup_ms", "make_ms", "snapshot_bytes", "dense_fp32_bytes", "active",
                        "bricks_total", "vm_hwm_bytes"})
    if (kv.count(k)) csv.row("big", std::to_string(b->dim) + "^3", "0", "", k, kv.at(k), "", get("device"));
  csv.row("big", std::to_string(b->dim) + "^3", "0", "", "peak_rss_bytes", std::to_string(b->child.peak_rss_bytes),
          "B", "");
  csv.row("big", std::to_string(b->dim) + "^3", "0", "", "exit_code", std::to_string(b->child.exit_code), "", "");
}

const IsoResult* find_iso(const std::vector<CaseResult>& res, const std::string& name, double tau) {
  for (const auto& r : res)
    if (r.name == name)
      for (const auto& ir : r.isos)
        if (ir.iso.tau == tau) return &ir;
  return nullptr;
}

void print_verdicts(const std::vector<CaseResult>& res, const BigResult* big, std::uint64_t mem_total,
                    std::ostream& out, Csv& csv) {
  out << "\n## Verdicts (computed from the figures above)\n\n";
  std::vector<Verdict> vs;
  const IsoResult* a = find_iso(res, "chest", -500);
  vs.push_back(verdict_at_most("chest -500 sparse GPU / dense CPU", a ? a->sparse_gpu_over_dense_cpu : kNaN,
                               1.0 / 3.0, 3, a ? "sparse GPU: " + a->gpu.why : "chest CT not benchmarked"));
  const CaseResult* chest = nullptr;
  for (const auto& r : res)
    if (r.name == "chest") chest = &r;
  const std::string no_chest = "chest CT not benchmarked";
  vs.push_back(verdict_at_most("chest dense GPU chain / fastest peer chain", chest ? chest->chain_over_peer : kNaN,
                               1.0 / 3.0, 3, chest ? "no peer or no GPU time" : no_chest));
  vs.push_back(verdict_at_most("chest dense GPU chain / memcpy of its bytes", chest ? chest->chain_over_memcpy : kNaN,
                               5.0, 2, chest ? "no GPU time" : no_chest));
  // The device's own limit beside the target: its copy floor in the same units.
  if (chest && std::isfinite(chest->floor_over_memcpy)) {
    std::ostringstream f;
    f << std::fixed << std::setprecision(2) << "; the device's copy floor (copy_x4: the gradient's bytes, loads and "
      << "stores without arithmetic) = " << chest->floor_over_memcpy << " x memcpy of the same bytes, the chain = "
      << ratio(chest->chain_over_memcpy, chest->floor_over_memcpy) << " x that floor";
    vs.back().text += f.str();
  }
  // The whole chain's floor: where it is above the target, the target is below what this
  // device's loads and stores of the chain's bytes cost, whatever the shaders compute.
  if (chest && std::isfinite(chest->chain_floor_over_memcpy)) {
    std::ostringstream f;
    f << std::fixed << std::setprecision(2) << "; the device's floor for the whole chain's bytes (copy_x4 once per "
      << "pass with its loads and stores) = " << chest->chain_floor_over_memcpy << " x memcpy, the chain = "
      << chest->chain_over_floor << " x that floor"
      << (chest->chain_floor_over_memcpy > 5.0 ? ": the target is below this device's floor" : "");
    vs.back().text += f.str();
  }
  // The issue's two targets for the dense chain on this run's CPU (its model in the text).
  const std::string cpu = "CPU " + cpu_model();
  vs.push_back(verdict_at_most("chest dense GPU chain / the device's copy floor for its bytes (" + cpu + ")",
                               chest ? chest->chain_over_floor : kNaN, 2.0, 3, chest ? "no GPU time or floor" : no_chest));
  if (chest && std::isfinite(chest->chain_over_passes_floor)) {
    std::ostringstream f;
    f << std::fixed << std::setprecision(3) << "; against the floor of its passes as run (the Gaussian's x, y "
      << "and z each a filter pass's loads and stores) = " << chest->chain_over_passes_floor;
    vs.back().text += f.str();
  }
  vs.push_back(verdict_at_most("chest dense GPU chain / best standalone pass set, same run (" + cpu + ")",
                               chest ? chest->chain_over_standalone : kNaN, 1.0, 3,
                               chest ? "standalone set: " + chest->standalone.why : no_chest));
  if (chest && chest->standalone.why.empty() && !chest->standalone.all_same_bits)
    vs.back().text += "; a standalone pass's output DIFFERS from the CPU chain's";
  vs.push_back(verdict_at_most("chest -500 sparse GPU / fastest peer chain",
                               a && chest ? ratio(a->gpu.total_ms, chest->fastest_peer_chain_ms) : kNaN, 1.0 / 5.0, 3,
                               a ? "sparse GPU: " + a->gpu.why + " or no peer" : no_chest));
  for (double tau : {1150.0, 500.0}) {
    const IsoResult* h = find_iso(res, "head", tau);
    std::ostringstream what;
    what << "head " << tau << " sparse GPU / sparse CPU";
    vs.push_back(verdict_at_most(what.str(), h ? ratio(h->gpu.total_ms, h->cpu.total_ms) : kNaN, 1.0, 3,
                                 h ? "sparse: " + h->gpu.why + h->cpu.why : "head CT not benchmarked"));
  }
  // The stricter reading of "GPU no slower than CPU": against the fastest CPU path measured
  // here for the same snapshot's samples, the dense one-thread CPU chain.
  for (double tau : {1150.0, 500.0}) {
    const IsoResult* h = find_iso(res, "head", tau);
    std::ostringstream what;
    what << "head " << tau << " sparse GPU / dense CPU chain";
    vs.push_back(verdict_at_most(what.str(), h ? h->sparse_gpu_over_dense_cpu : kNaN, 1.0, 3,
                                 h ? "sparse GPU: " + h->gpu.why : "head CT not benchmarked"));
  }
  const IsoResult* b = find_iso(res, "chest", 250);
  double best = kNaN;
  std::string best_fmt, why = b ? "" : "chest CT not benchmarked";
  if (b)
    for (const auto& f : b->formats) {
      if (f.available && (!std::isfinite(best) || f.percent < best)) {
        best = f.percent;
        best_fmt = format_name(f.format);
      }
      if (!f.available && why.empty()) why = f.why;
    }
  vs.push_back(verdict_at_most("chest +250 snapshot / dense fp32 bytes (" +
                                   (best_fmt.empty() ? std::string("no format") : "smallest: " + best_fmt) + ")",
                               best / 100.0, 0.15, 3, why));
  if (big) {
    const bool ran = big->child.started && big->child.exit_code == 0 && big->kv.count("snapshot_bytes");
    const double frac = ran ? ratio(double(big->child.peak_rss_bytes), double(mem_total)) : kNaN;
    vs.push_back(verdict_at_most(std::to_string(big->dim) + "^3 end to end (" + (big->kv.count("engine") ? big->kv.at("engine") : std::string("no engine")) +
                                     "), peak RSS / MemTotal",
                                 frac, 1.0, 3, big->note.empty() ? "no snapshot" : big->note));
  } else {
    vs.push_back(verdict_at_most("512^3 end to end, peak RSS / MemTotal", kNaN, 1.0, 3, "not run: --quick"));
  }
  for (const auto& v : vs) {
    out << "- " << v.text << "\n";
    csv.row("verdict", "", "", v.text, "met", v.measured ? (v.met ? "1" : "0") : "", "", "");
  }
}
}  // namespace

int run_bench_engine(const BenchEngineOptions& o_in, std::ostream& out, std::ostream& progress) {
  BenchEngineOptions o = o_in;
  if (o.quick) o.repetitions = 1;
  const std::uint64_t mem_total = mem_total_bytes();
  // The 512^3 child first, while this process is small (its RSS at fork counts in the
  // child's ru_maxrss).
  std::unique_ptr<BigResult> big;
  if (!o.quick || o.big) big = std::make_unique<BigResult>(run_big(o, progress));

  progress << "[bench engine] memcpy bandwidth\n" << std::flush;
  const std::size_t memcpy_bytes = std::size_t(256) << 20;
  const double memcpy_gbps = measure_memcpy_gbps(memcpy_bytes, 5);

  engine::ContextOptions co;
  co.device = o.device;
  auto ctx_r = engine::VulkanContext::create(co);
  engine::VulkanContext* ctx = ctx_r ? ctx_r.value->get() : nullptr;
  const std::string gpu_why = ctx ? "" : "Vulkan: " + ctx_r.error;
  Devices dev;
  dev.gpu = ctx ? ctx->info().name + " (" + ctx->info().type + ", " + ctx->info().driver + ")" : "no Vulkan device";
  dev.cpu = "one thread, " + cpu_model();

  // Volumes.
  struct Vol {
    std::string name, source;
    std::vector<core::Isosurface> isos;
    engine::Volume v;
    std::string error;
  };
  const core::InsideIs above = core::InsideIs::kAbove;
  std::vector<Vol> vols;
  vols.push_back({"head", "data/ct-head-headsq/headsq_64x64x93_int16.mhd", {{1150, above}, {500, above}}, {}, {}});
  vols.push_back({"chest",
                  "data/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd",
                  {{-500, above}, {250, above}},
                  {},
                  {}});
  const auto wanted = [&](const std::string& name) {
    return o.cases.empty() || std::find(o.cases.begin(), o.cases.end(), name) != o.cases.end();
  };
  vols.erase(std::remove_if(vols.begin(), vols.end(), [&](const Vol& v) { return !wanted(v.name); }), vols.end());
  int rc = 0;
  for (auto& v : vols) {
    try {
      v.v = io::load_volume(resolve_data(v.source));
    } catch (const std::exception& e) {
      v.error = e.what();
      rc = 1;
    }
  }
  if (wanted("sphere256")) {
    progress << "[bench engine] making the 256^3 noisy sphere\n" << std::flush;
    vols.push_back({"sphere256", "", {{0, above}}, make_noisy_sphere(256, 1e-3), {}});
    vols.back().source = vols.back().v.path + ", 1 mm spacing";
  }
  const std::string load_before = load_average();

  std::vector<CaseResult> res;
  for (bool closing : {false, true}) {
    if (closing && !o.with_closing) break;
    for (const auto& v : vols) {
      if (!v.error.empty()) continue;
      BenchCase c{v.name + (closing ? "+closing" : ""), v.source, &v.v, v.isos};
      res.push_back(run_case(ctx, gpu_why, c, closing, o.repetitions, memcpy_gbps, progress, o.peers));
    }
  }

  Csv csv;
  out << "# isotouch bench engine\n\n"
      << "- GPU columns: " << dev.gpu << (ctx && ctx->info().type == "cpu" ? " - a CPU device (lavapipe), not a GPU" : "")
      << (ctx ? ", timestamps " + std::string(ctx->timestamps_supported() ? "on" : "off") : "") << "\n"
      << "- CPU columns: " << dev.cpu << "\n"
      << "- machine: " << std::thread::hardware_concurrency() << " hardware threads, MemTotal " << mib(mem_total)
      << " MiB; load average (1, 5, 15 min) " << load_before << " before the cases, " << load_average()
      << " after (other work on the machine slows every column)\n"
      << "- memcpy: " << num(memcpy_gbps) << " GB/s (std::memcpy of " << (memcpy_bytes >> 20)
      << " MiB, best of 5, read + write bytes counted), measured in this run\n"
      << "- repetitions: " << o.repetitions << " per figure, interleaved (dense GPU, dense CPU, sparse GPU, sparse "
      << "CPU), medians; one untimed GPU warm-up\n"
      << "- dense pass list: " << list_label(dense_list(false)) << "; sparse: " << list_label(sparse_list(false))
      << " (brick min/max implied)" << (o.with_closing ? "; second list with closing(radius 1 mm)" : "") << "\n";
  for (const auto& v : vols) {
    out << "- " << v.name << ": ";
    if (!v.error.empty()) {
      out << "not benchmarked: " << v.error << "\n";
      continue;
    }
    const auto& d = v.v.grid.dims;
    out << v.source << " (" << d[0] << "x" << d[1] << "x" << d[2] << ", spacing " << num(v.v.grid.spacing_m.x * 1e3, 3)
        << " x " << num(v.v.grid.spacing_m.y * 1e3, 3) << " x " << num(v.v.grid.spacing_m.z * 1e3, 3)
        << " mm), isovalues";
    for (const auto& i : v.isos) out << " " << tau_text(i) << " (inside " << core::to_string(i.inside) << ")";
    out << "\n";
  }
  csv.row("memcpy", "", "", "", "memcpy_gbps", csv_num(memcpy_gbps), "GB/s", dev.cpu);
  print_dense(res, dev, out, csv);
  print_peers(res, dev, out, csv);
  print_standalone(res, dev, out, csv);
  print_cpu_backend(res, dev, out, csv);
  print_sparse(res, dev, out, csv);
  print_bytes(res, out, csv);
  print_big(big.get(), out, csv, mem_total);
  print_verdicts(res, big.get(), mem_total, out, csv);
  out << "\nmin bytes: gaussian/closing 8 B per voxel (read + write fp32), gradient 20 B (read fp32, write a 16 B "
         "sample), brick_minmax 4 B per voxel + 8 B per brick. GB/s = min bytes / median time; / memcpy = that "
         "over the memcpy figure above. GPU pass times are device timestamps; end to end and sparse totals are "
         "wall clock with all host work. Timings on a shared machine are noisy.\n";
  if (!o.out_csv.empty()) {
    write_file_atomic(o.out_csv, csv.s.str());
    progress << "[bench engine] wrote " << o.out_csv << "\n";
  }
  // A figure that could not be measured because something failed is a failure, not a
  // "not measured" verdict: exit 1 and say which.
  for (const auto& r : res)
    for (std::size_t k = 0; k < r.isos.size(); ++k) {
      const IsoResult& ir = r.isos[k];
      if ((ctx && !ir.gpu.available) || !ir.cpu.available) {
        out << "\nFAILED: " << r.name << " #" << k << ": sparse GPU: " << (ir.gpu.available ? "ok" : ir.gpu.why)
            << "; sparse CPU: " << (ir.cpu.available ? "ok" : ir.cpu.why) << "\n";
        rc = 1;
      }
    }
  if (big && big->child.started && (big->child.exit_code != 0 || big->child.signal != 0)) {
    out << "\nFAILED: " << big->dim << "^3 end to end: child exit " << big->child.exit_code << ", signal "
        << big->child.signal << "\n";
    rc = 1;
  }
  return rc;
}


}  // namespace isotouch::bench
