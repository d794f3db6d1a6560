// bench_engine.h - `isotouch bench engine`: the engine's passes dense and
// sparse, on the GPU (Vulkan; lavapipe here) and in the one-thread CPU reference, on the head
// CT, the chest CT and a 256^3 synthetic volume; bricks active, published snapshot bytes
// against dense fp32, each pass's effective bandwidth against this machine's memcpy
// bandwidth measured in the same run; a 512^3 volume end to end in a child process (time,
// peak RSS). The computing parts are functions here so tests/test_bench_engine.cpp can check
// them against independent computations.
#pragma once
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "isotouch/eval/stats.h"
#include "isotouch/bench/bench_reference.h"
#include "isotouch/core/brick_field.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/volume.h"

namespace isotouch::bench {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// ---------------------------------------------------------------------------------------
// Formulas

/// Bytes a dense pass must move at the least over a volume of `voxels` voxels and `bricks`
/// 8^3 bricks: every input read once and every output written once (fp32 = 4 B):
/// gaussian and closing read 4 B and write 4 B per voxel (8 N); gradient reads 4 B and
/// writes a 16 B sample per voxel (20 N); brick_minmax reads 4 B per voxel and writes 8 B
/// (min, max) per brick (4 N + 8 B). Halo re-reads and the separable passes' intermediate
/// round trips are not counted: this is the floor a perfect implementation would move.
std::uint64_t pass_min_bytes(engine::PassKind kind, std::uint64_t voxels, std::uint64_t bricks);

/// Effective bandwidth [GB/s, 1e9 B/s] of moving `bytes` in `ms` milliseconds; NaN if ms is
/// not positive or not finite.
double gb_per_s(double bytes, double ms);

/// Copy bandwidth of this machine [GB/s]: std::memcpy of `bytes` bytes between two buffers
/// touched beforehand, best of `tries`; counted as read + write = 2 x bytes per copy (the
/// same convention as pass_min_bytes).
double measure_memcpy_gbps(std::size_t bytes, int tries);

/// a / b, NaN unless both are finite and b > 0.
double ratio(double a, double b);

// ---------------------------------------------------------------------------------------
// Verdicts

struct Verdict {
  bool measured = false;  ///< false if the figure could not be measured
  bool met = false;       ///< measured && value <= target
  std::string text;       ///< "<what> = 0.xx: target <= 0.33 met" / "NOT met" / "not measured (why)"
};
/// The verdict on "value <= target", built from the measured value. `digits`: decimals
/// printed. `why_missing` is said when `value` is NaN.
Verdict verdict_at_most(const std::string& what, double value, double target, int digits = 2,
                        const std::string& why_missing = "");

// ---------------------------------------------------------------------------------------
// Child processes and peak memory

struct ChildRun {
  bool started = false;          ///< fork/exec succeeded
  int exit_code = -1;            ///< exit status, or -1 if killed by a signal
  int signal = 0;                ///< terminating signal, 0 if none
  double wall_ms = kNaN;         ///< fork to reap, wall clock
  std::uint64_t peak_rss_bytes = 0;  ///< wait4() ru_maxrss (KiB on Linux) x 1024
  std::string out;               ///< what the child wrote to its stdout
  std::string error;             ///< why it did not start
  double cpu_s = kNaN;           ///< wait4() user + system time of the child and the descendants it reaped [s]
};
/// Fork; the child runs `body` with stdout redirected into a pipe and exits with its
/// return value (1 on an exception); the parent collects stdout and reaps the child with
/// wait4(), whose rusage gives the child's peak resident set. Linux counts in that peak the
/// parent's pages the child held right after fork (copy-on-write), so run it while the
/// parent is small.
ChildRun run_child_fork(const std::function<int()>& body);
/// Fork and execv(argv[0], argv) (no PATH lookup), stdout into a pipe, reaped with wait4().
/// Linux keeps the larger of the pre-exec and post-exec peaks in ru_maxrss.
ChildRun run_child_exec(const std::vector<std::string>& argv);
/// This process's own peak resident set [bytes] from /proc/self/status VmHWM (0 if unknown).
std::uint64_t self_peak_rss_bytes();
/// "key=value" lines of a child's stdout.
std::map<std::string, std::string> parse_key_values(const std::string& text);

// ---------------------------------------------------------------------------------------
// Volumes and cases

/// The synthetic bench volume: the signed distance [mm, positive inside] to a sphere of
/// radius 0.375 n voxels around the grid centre (engine::make_sphere), plus uniform noise in
/// [-noise_mm, noise_mm) from a hash of the voxel index and `seed` (reproducible, no RNG
/// state), on an n^3 grid of spacing `spacing_m` [m]. Isosurface tau = 0, inside above.
engine::Volume make_noisy_sphere(int n, double spacing_m, double noise_mm = 1.0, std::uint32_t seed = 1);

/// One volume and the isovalues it is benchmarked at.
struct BenchCase {
  std::string name;                       ///< "head", "chest", "sphere256"
  std::string source;                     ///< file path or synthetic recipe
  const engine::Volume* volume = nullptr;
  std::vector<core::Isosurface> isos;
};

/// Sparse figures at one isovalue for one engine (GPU or CPU reference).
struct SparseCell {
  bool available = false;
  std::string why;                        ///< reason when not available
  double total_ms = kNaN;                 ///< median SparseOutput::total_ms (wall, all host work)
  std::vector<std::string> stage_labels;  ///< SparseOutput::passes labels
  std::vector<double> stage_ms;           ///< median per stage
  engine::SparseStats stats;              ///< of the last run (fp32)
};

/// Published snapshot bytes of one sample format.
struct FormatBytes {
  core::SampleFormat format = core::SampleFormat::kFp32;
  bool available = false;
  std::string why;
  std::string engine;                     ///< "GPU" or "CPU reference": which run gave them
  std::uint64_t snapshot_bytes = 0;
  std::uint64_t dense_fp32_bytes = 0;
  double percent = kNaN;                  ///< 100 snapshot / dense fp32
};

struct IsoResult {
  core::Isosurface iso;
  SparseCell cpu;                         ///< the CPU reference (run_sparse_cpu, one thread)
  SparseCell cpu_mt;                      ///< the multi-threaded CPU backend (run_sparse_cpu, CaseResult::cpu_backend_threads)
  SparseCell gpu;                         ///< the GPU chain's default strategy (SparseChain::Strategy::Lists)
  SparseCell gpu_dense;                   ///< the same on the dense x4 passes over the whole volume (Strategy::Dense)
  SparseCell gpu_per_brick;               ///< the same on the per-brick kernel (SparseChain::Strategy::PerBrick)
  std::vector<FormatBytes> formats;       ///< fp32, fp16, unorm16
  double active_percent = kNaN;           ///< 100 active / bricks_total
  double candidate_percent = kNaN;        ///< 100 candidates / bricks_total
  double sparse_gpu_over_dense_cpu = kNaN;  ///< sparse GPU total / dense CPU wall
  double sparse_cpu_over_dense_cpu = kNaN;  ///< sparse CPU total / dense CPU wall
  double sparse_gpu_over_dense_gpu = kNaN;  ///< sparse GPU total / dense GPU wall
  std::string gpu_cpu_counts;             ///< "same" / how GPU and CPU brick counts differ / ""
};

/// One dense pass (or the total) of one case.
struct PassRow {
  std::string label;
  std::uint64_t min_bytes = 0;            ///< pass_min_bytes (total: the sum)
  double gpu_ms = kNaN, cpu_ms = kNaN;    ///< medians; GPU: device timestamps
  double gpu_gbps = kNaN, cpu_gbps = kNaN;  ///< min_bytes / time
  double gpu_of_memcpy = kNaN, cpu_of_memcpy = kNaN;  ///< gbps / memcpy gbps
  double gpu_over_cpu = kNaN;             ///< gpu_ms / cpu_ms
  double legacy_gpu_ms = kNaN;            ///< median device time of the legacy shaders (ShaderSet::Legacy)
  double legacy_over_gpu = kNaN;          ///< legacy_gpu_ms / gpu_ms: the rewrite's speed-up
};

/// The peers at one thread count (medians of run_peers_once, bench_peers.h) and their chains.
struct PeerRow {
  int threads = 1;
  double itk_gaussian_ms = kNaN, itk_gradient_ms = kNaN, itk_pack_ms = kNaN;
  double vdb_from_dense_ms = kNaN, vdb_gradient_ms = kNaN;
  double itk_chain_ms = kNaN;      ///< ITK Gaussian + ITK gradient + packing into samples
  double itk_vdb_chain_ms = kNaN;  ///< ITK Gaussian + OpenVDB copyFromDense + gradient
  std::string why;                 ///< a peer that could not run, and why
};

struct CaseResult {
  std::string name, source, list_label;   ///< list_label: the dense pass list
  std::array<int, 3> dims{0, 0, 0};
  std::uint64_t voxels = 0, bricks = 0;
  bool gpu_available = false;
  std::string gpu_why;
  std::vector<PassRow> passes;            ///< one per dense pass
  PassRow sum;                            ///< sum over the passes (bytes and times)
  double dense_gpu_wall_ms = kNaN;        ///< median wall of PassChain::run (upload..download)
  double dense_cpu_wall_ms = kNaN;        ///< median wall of run_chain_cpu
  unsigned cpu_backend_threads = 0;       ///< threads of the multi-threaded CPU backend (0: not run)
  double dense_cpu_mt_wall_ms = kNaN;     ///< median wall of run_chain_cpu on cpu_backend_threads threads
  bool cpu_backend_same_bits = false;     ///< every repetition's output bit for bit the one-thread reference's
  /// The sparse GPU chain (lists strategy) over all its runs here: runs whose brick pool was
  /// the retained buffer of a snapshot already destroyed (engine/pool_recycler.h), runs in
  /// all, and the bytes it retains after the last one (held for no snapshot: in the RSS).
  std::uint64_t sparse_recycled_pools = 0, sparse_runs = 0, sparse_retained_bytes = 0;
  double dense_gpu_over_cpu_wall = kNaN;  ///< dense_gpu_wall_ms / dense_cpu_wall_ms
  std::vector<IsoResult> isos;
  double memcpy_gbps = kNaN;
  double legacy_gpu_wall_ms = kNaN;       ///< median wall of the legacy-shader PassChain::run
  std::vector<PeerRow> peers;             ///< 1 and 2 threads
  double fastest_peer_chain_ms = kNaN;    ///< min over the peer rows' chains
  std::string fastest_peer_chain;         ///< which one
  double chain_over_peer = kNaN;          ///< sum.gpu_ms / fastest_peer_chain_ms
  double memcpy_ms = kNaN;                ///< time memcpy takes for sum.min_bytes at memcpy_gbps
  double chain_over_memcpy = kNaN;        ///< sum.gpu_ms / memcpy_ms
  /// The device's floor for the gradient's bytes: GradientPass::copy_floor_ms (copy_x4.comp,
  /// the gradient's texel loads and vec4 stores without arithmetic), median device time.
  double copy_floor_ms = kNaN;
  double copy_floor_memcpy_ms = kNaN;     ///< memcpy time of the same bytes (gradient min bytes)
  double floor_over_memcpy = kNaN;        ///< copy_floor_ms / copy_floor_memcpy_ms
  double gradient_over_floor = kNaN;      ///< the gradient pass (current shaders) / copy_floor_ms
  /// The device's floor for the whole dense chain's bytes: per pass copy_x4.comp with that
  /// pass's loads and stores (GradientPass::FloorTraffic: a filter 4 + 4 B, the gradient
  /// 4 + 16 B, brick min/max 4 B per voxel), no arithmetic, medians summed [ms].
  double chain_floor_ms = kNaN;
  double chain_floor_over_memcpy = kNaN;  ///< chain_floor_ms / memcpy_ms (memcpy of sum.min_bytes)
  double chain_over_floor = kNaN;         ///< sum.gpu_ms / chain_floor_ms
  /// The floor of the passes over the field as the chain runs them: as chain_floor_ms with a
  /// Gaussian's three axis passes (a closing's six) each a filter pass [ms].
  double chain_passes_floor_ms = kNaN;
  double chain_over_passes_floor = kNaN;  ///< sum.gpu_ms / chain_passes_floor_ms
  /// The same work as standalone passes in the fastest forms measured on lavapipe
  /// (bench_reference.h), timed in the same repetitions; `standalone.why` says why not.
  StandaloneFigures standalone;
  /// The chain's device time in each run paired with a standalone set's run beside it [ms]
  /// (the same order as standalone.set_ms_per_run).
  std::vector<double> chain_pair_ms;
  /// The median over those pairs of chain / set (each pair at the same moment's load).
  double chain_over_standalone = kNaN;
};

/// The dense pass list: filters, gradient, brick_minmax(1); the sparse list is the same
/// without brick_minmax (implied there).
std::vector<engine::PassDesc> dense_list(bool with_closing);
std::vector<engine::PassDesc> sparse_list(bool with_closing);

/// Runs one case: per repetition, interleaved, dense GPU (PassChain::run, current shaders),
/// dense GPU with the legacy shaders, dense CPU (run_chain_cpu), the peers at 1 and 2
/// threads (bench_peers.h; `peers` false skips them), then per isovalue sparse GPU (SparseChain::run, fp32) and sparse CPU
/// (run_sparse_cpu, fp32); one untimed warm-up of each GPU chain first; fp16 and unorm16
/// once each for their bytes. `ctx` null: no GPU figures (gpu_why says why). Exceptions of
/// the sparse engines (e.g. "not implemented yet") are caught and reported in the cells.
/// Derived columns are filled by finish_case(). Progress lines go to `progress`.
CaseResult run_case(engine::VulkanContext* ctx, const std::string& gpu_why, const BenchCase& c, bool with_closing,
                    int repetitions, double memcpy_gbps, std::ostream& progress, bool peers = true);

/// Fills every derived column (bandwidths, fractions of memcpy, ratios, percents) from the
/// measured ones: sum row, active/candidate %, bytes %, the ratios. Idempotent.
void finish_case(CaseResult& r);

// ---------------------------------------------------------------------------------------
// The 512^3 end-to-end step

struct BigResult {
  int dim = 512;
  ChildRun child;
  std::map<std::string, std::string> kv;  ///< the child's report (see run_big_child)
  std::string note;                       ///< why not run / what failed
};
/// In this process (the child of run_big): make the n^3 noisy sphere, create the Vulkan
/// context and the sparse GPU chain, run it once to a published fp32 snapshot; if the GPU
/// sparse chain is not available, run_sparse_cpu instead; then hand the snapshot to the
/// servo (servo::TripleBuffer) and time the first HRI ticks on it. Writes key=value lines to
/// `out` (engine, make_ms, setup_ms, step_ms, stages and stage<i>_ms / stage<i>_label (the
/// chain's own stages), snapshot_bytes, dense_fp32_bytes, bricks_total, candidates, active,
/// publish_ms, first_tick_us, ticks_median_us, max_force_n, vm_hwm_bytes, device, note).
/// @return 0 if a snapshot was published.
int run_big_child(int n, const std::string& device, std::ostream& out, std::ostream& progress);

struct BenchEngineOptions {
  std::string device;
  int repetitions = 3;
  bool quick = false;       ///< repetitions 1, no 512^3 unless `big`
  bool big = false;         ///< run the 512^3 step even with --quick
  bool with_closing = false;  ///< also benchmark the list with closing(1 mm)
  bool peers = true;        ///< time ITK and OpenVDB beside the engine
  int big_dim = 512;
  std::vector<std::string> cases;  ///< "head", "chest", "sphere256"; empty: all
  std::string out_csv;
  std::string self_exe = "/proc/self/exe";  ///< what run_big re-executes
};

/// The whole bench; prints the markdown report to `out`, progress to `progress`.
/// @return 0, or 1 if a volume could not be read.
int run_bench_engine(const BenchEngineOptions& o, std::ostream& out, std::ostream& progress);

}  // namespace isotouch::bench
