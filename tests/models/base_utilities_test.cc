// The base utilities of models/ every later folder uses: atomic files, deterministic
// parallel loops and seeded randomness.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/io.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

std::string ReadAll(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(WriteFileAtomically, WritesWholeFileAndLeavesNoTemporary) {
  const auto dir = std::filesystem::path(testing::TempDir()) / "atomic_ok";
  std::filesystem::create_directories(dir);
  const auto path = dir / "out.txt";
  WriteFileAtomically(path, [](std::ostream& out) { out << "hello\n"; });
  EXPECT_EQ(ReadAll(path), "hello\n");
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) files += entry.is_regular_file();
  EXPECT_EQ(files, 1);
}

TEST(WriteFileAtomically, FailedWriteKeepsOldFile) {
  const auto dir = std::filesystem::path(testing::TempDir()) / "atomic_fail";
  std::filesystem::create_directories(dir);
  const auto path = dir / "out.txt";
  WriteFileAtomically(path, [](std::ostream& out) { out << "old"; });
  EXPECT_THROW(WriteFileAtomically(path,
                                   [](std::ostream& out) {
                                     out << "half";
                                     throw std::runtime_error("disk full");
                                   }),
               std::runtime_error);
  EXPECT_EQ(ReadAll(path), "old");
  EXPECT_FALSE(std::filesystem::exists(dir / ".out.txt.tmp"));
}

TEST(WriteFileAtomically, MissingDirectoryIsNamed) {
  try {
    WriteFileAtomically("/nonexistent_dir_for_test/x.json", [](std::ostream&) {});
    FAIL() << "no exception";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent_dir_for_test"), std::string::npos);
  }
}

// A floating-point sum whose result depends on the order of additions.
double ChunkedSum(int threads) {
  const int n = 10007;
  std::vector<double> partial(NumChunks(n, 97), 0.0);
  ParallelForChunks(n, 97, threads, [&](int chunk, int begin, int end) {
    for (int i = begin; i < end; ++i) partial[chunk] += 1.0 / (1.0 + i) * std::sin(i);
  });
  return std::accumulate(partial.begin(), partial.end(), 0.0);
}

TEST(ParallelForChunks, SameBitsAtAnyThreadCount) {
  const double one = ChunkedSum(1);
  for (int threads : {2, 3, 8}) EXPECT_EQ(ChunkedSum(threads), one) << threads << " threads";
}

TEST(ParallelForChunks, CoversEveryItemOnce) {
  std::vector<int> hits(1000, 0);
  ParallelForChunks(1000, 33, 4, [&](int, int begin, int end) {
    for (int i = begin; i < end; ++i) ++hits[i];
  });
  for (int h : hits) ASSERT_EQ(h, 1);
  EXPECT_EQ(NumChunks(1000, 33), 31);
  EXPECT_EQ(NumChunks(0, 33), 0);
}

TEST(ParallelForChunks, RethrowsWorkerException) {
  EXPECT_THROW(ParallelForChunks(100, 10, 2,
                                 [](int chunk, int, int) {
                                   if (chunk == 7) throw Error("chunk 7 failed");
                                 }),
               Error);
}

// Loops inside loops, and loops from several threads at once, each complete
// with every item once (the worker pool is busy, so they start their own threads).
TEST(ParallelForChunks, NestedAndConcurrentLoopsCoverEveryItem) {
  constexpr int kOuter = 6, kInner = 500;
  std::vector<std::vector<int>> hits(kOuter, std::vector<int>(kInner, 0));
  ParallelForChunks(kOuter, 1, 2, [&](int, int begin, int) {
    ParallelForChunks(kInner, 64, 2, [&](int, int b, int e) {
      for (int i = b; i < e; ++i) ++hits[begin][i];
    });
  });
  for (const auto& row : hits) EXPECT_EQ(std::count(row.begin(), row.end(), 1), kInner);

  std::vector<double> sums(4, 0.0);
  std::vector<std::thread> callers;
  for (int t = 0; t < 4; ++t) {
    callers.emplace_back([&sums, t] {
      for (int rep = 0; rep < 50; ++rep) sums[t] += ChunkedSum(2);
    });
  }
  for (auto& c : callers) c.join();
  double expected = 0.0;
  for (int rep = 0; rep < 50; ++rep) expected += ChunkedSum(1);
  for (double s : sums) EXPECT_EQ(s, expected);
}

TEST(Random, SameSeedSameStream) {
  Rng a(42), b(42);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(StandardNormal(a), StandardNormal(b));
  Rng d(1), e(2);
  EXPECT_NE(UniformUnit(d), UniformUnit(e));
}

TEST(Random, NormalHasUnitMomentsAndUniformRange) {
  Rng rng(7);
  const int n = 200000;
  double mean = 0, var = 0;
  for (int i = 0; i < n; ++i) {
    const double x = StandardNormal(rng);
    mean += x;
    var += x * x;
  }
  mean /= n;
  var = var / n - mean * mean;
  EXPECT_NEAR(mean, 0.0, 5.0 / std::sqrt(n));
  EXPECT_NEAR(var, 1.0, 0.02);
  for (int i = 0; i < 1000; ++i) {
    const double u = Uniform(rng, -2.0, 3.0);
    ASSERT_GE(u, -2.0);
    ASSERT_LT(u, 3.0);
  }
}

// SplitMix64 is the published generator: from state 0 its first outputs are the
// reference values of Vigna's splitmix64.c.
TEST(Random, SplitMix64MatchesTheReferenceStream) {
  SplitMix64 g(0);
  EXPECT_EQ(g(), 0xE220A8397B1DCDAFULL);
  EXPECT_EQ(g(), 0x6E789E6AA1B965F4ULL);
  EXPECT_EQ(SplitMix64Hash(0), 0xE220A8397B1DCDAFULL);
}

// Both outputs of each Box-Muller pair are used, and the pairs are independent
// normals: unit moments and no correlation between the two members.
TEST(Random, FillStandardNormalUsesBothPairOutputs) {
  SplitMix64 g(11);
  const int n = 200001;  // odd: the last sine is dropped
  std::vector<double> z(n);
  FillStandardNormal(g, z.data(), n);
  double mean = 0, var = 0, cross = 0;
  for (int i = 0; i < n; ++i) mean += z[i], var += z[i] * z[i];
  for (int i = 0; i + 1 < n; i += 2) cross += z[i] * z[i + 1];
  mean /= n;
  var = var / n - mean * mean;
  cross /= n / 2;
  EXPECT_NEAR(mean, 0.0, 5.0 / std::sqrt(n));
  EXPECT_NEAR(var, 1.0, 0.02);
  EXPECT_NEAR(cross, 0.0, 5.0 / std::sqrt(n / 2));
  // The first pair is r (cos a, sin a) from the first two uniforms.
  SplitMix64 h(11);
  const double u1 = 1.0 - UniformUnit(h), u2 = UniformUnit(h);
  const double r = std::sqrt(-2.0 * std::log(u1));
  EXPECT_DOUBLE_EQ(z[0], r * std::cos(2.0 * std::numbers::pi * u2));
  EXPECT_DOUBLE_EQ(z[1], r * std::sin(2.0 * std::numbers::pi * u2));
}

TEST(Random, ShuffleIsSeededPermutation) {
  std::vector<int> a(50), b(50);
  std::iota(a.begin(), a.end(), 0);
  std::iota(b.begin(), b.end(), 0);
  Rng r1(5), r2(5);
  Shuffle(a.begin(), a.end(), r1);
  Shuffle(b.begin(), b.end(), r2);
  EXPECT_EQ(a, b);
  std::vector<int> sorted = a;
  std::sort(sorted.begin(), sorted.end());
  for (int i = 0; i < 50; ++i) EXPECT_EQ(sorted[i], i);
  int moved = 0;
  for (int i = 0; i < 50; ++i) moved += a[i] != i;
  EXPECT_GT(moved, 25);
}

}  // namespace
}  // namespace diffdyn
