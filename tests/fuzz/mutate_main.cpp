// A mutation-fuzzing main() for fuzz targets that clang cannot build (Debian's ITK headers
// accept GCC only): it drives LLVMFuzzerTestOneInput like libFuzzer does, without coverage
// guidance. Every seed runs once, then random mutations of the seeds (bit flips, random
// bytes, interesting integers, inserted / erased / duplicated ranges, truncation) until the
// time is up. Built with ASan + UBSan; a crash or a sanitizer report ends the process with a
// non-zero status, and with -artifact_prefix=P the input being run is in P/current-input.
//
//   fuzz_volume [-max_total_time=S] [-seed=N] [-artifact_prefix=DIR/] CORPUS_DIR...
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

using Bytes = std::vector<std::uint8_t>;

void mutate(Bytes& b, std::mt19937_64& rng) {
  const int n = 1 + int(rng() % 4);
  for (int i = 0; i < n; ++i) {
    const std::size_t size = b.size();
    switch (rng() % 7) {
      case 0:  // flip a bit
        if (size) b[rng() % size] ^= std::uint8_t(1u << (rng() % 8));
        break;
      case 1:  // a random byte
        if (size) b[rng() % size] = std::uint8_t(rng());
        break;
      case 2: {  // an interesting integer, 1, 2, 4 or 8 bytes, little endian
        static const std::uint64_t kInteresting[] = {0, 1, 0x7f, 0x80, 0xff, 0x7fff, 0x8000, 0xffff, 0x7fffffff,
                                                     0x80000000, 0xffffffff, 0x7fffffffffffffff, ~0ull};
        const std::uint64_t v = kInteresting[rng() % std::size(kInteresting)];
        const std::size_t w = std::size_t(1) << (rng() % 4);
        if (size >= w) std::memcpy(&b[rng() % (size - w + 1)], &v, w);
        break;
      }
      case 3: {  // insert random bytes
        const std::size_t at = size ? rng() % (size + 1) : 0, len = 1 + rng() % 16;
        Bytes ins(len);
        for (auto& c : ins) c = std::uint8_t(rng());
        b.insert(b.begin() + std::ptrdiff_t(at), ins.begin(), ins.end());
        break;
      }
      case 4:  // erase a range
        if (size > 1) {
          const std::size_t at = rng() % size, len = 1 + rng() % std::min<std::size_t>(size - at, 64);
          b.erase(b.begin() + std::ptrdiff_t(at), b.begin() + std::ptrdiff_t(at + len));
        }
        break;
      case 5:  // truncate
        if (size > 1) b.resize(rng() % size);
        break;
      case 6:  // duplicate a range
        if (size > 1 && size < (1u << 20)) {
          const std::size_t at = rng() % size, len = 1 + rng() % std::min<std::size_t>(size - at, 256);
          const Bytes copy(b.begin() + std::ptrdiff_t(at), b.begin() + std::ptrdiff_t(at + len));
          b.insert(b.begin() + std::ptrdiff_t(rng() % size), copy.begin(), copy.end());
        }
        break;
    }
  }
}

Bytes read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 10;
  std::uint64_t seed = 1;
  std::string artifacts;
  std::vector<Bytes> seeds;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("-max_total_time=", 0) == 0) seconds = std::stod(a.substr(16));
    else if (a.rfind("-seed=", 0) == 0) seed = std::stoull(a.substr(6));
    else if (a.rfind("-artifact_prefix=", 0) == 0) artifacts = a.substr(17);
    else if (a[0] == '-') continue;  // other libFuzzer flags: accepted, ignored
    else if (std::filesystem::is_directory(a)) {
      for (const auto& e : std::filesystem::directory_iterator(a))
        if (e.is_regular_file()) seeds.push_back(read_file(e.path()));
    } else {
      seeds.push_back(read_file(a));
    }
  }
  if (seeds.empty()) seeds.emplace_back();
  std::mt19937_64 rng(seed);
  const auto keep = [&](const Bytes& b) {
    if (artifacts.empty()) return;
    std::ofstream out(artifacts + "current-input", std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
  };
  long runs = 0;
  for (const Bytes& s : seeds) {
    keep(s);
    LLVMFuzzerTestOneInput(s.data(), s.size());
    ++runs;
  }
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    Bytes b = seeds[rng() % seeds.size()];
    mutate(b, rng);
    keep(b);
    LLVMFuzzerTestOneInput(b.data(), b.size());
    ++runs;
  }
  std::printf("stat::number_of_executed_units: %ld\n", runs);
  std::printf("mutation fuzzing: %zu seeds, %ld runs, seed %llu, no failure\n", seeds.size(), runs,
              static_cast<unsigned long long>(seed));
  return 0;
}
