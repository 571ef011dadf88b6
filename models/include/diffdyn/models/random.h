// Seeded randomness.
//
// Every random thing in diffdyn takes a seed or a std::mt19937_64&; there is no
// std::random_device and no Eigen::Random. std::normal_distribution and friends
// are implementation-defined, so diffdyn draws its own from the raw 64-bit
// stream: the same seed gives the same numbers on every standard library.
//
// Many independent streams (one per trajectory, per MPPI sample, ...) come from
// SplitMix64: one word of state, so a stream costs nothing to start, and
// SplitMix64Hash turns (seed, index) into well-separated starting words:
//
//   SplitMix64 stream(SplitMix64Hash(SplitMix64Hash(seed) ^ sample));
//   FillStandardNormal(stream, z, 40);
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>

namespace diffdyn {

/// The generator used everywhere.
using Rng = std::mt19937_64;

/// SplitMix64's output function (Steele, Lea and Flood, 2014): a bijective
/// 64-bit mix of x + golden gamma, used to derive seeds of independent streams.
inline std::uint64_t SplitMix64Hash(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

/// The SplitMix64 generator: state s advances by the golden gamma and each
/// output is the mix of the new state. A 64-bit UniformRandomBitGenerator with
/// one word of state, for many short independent streams.
class SplitMix64 {
 public:
  using result_type = std::uint64_t;
  /// A stream starting from `seed`.
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  /// The next 64 random bits.
  result_type operator()() {
    const std::uint64_t out = SplitMix64Hash(state_);
    state_ += 0x9E3779B97F4A7C15ULL;
    return out;
  }
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return std::numeric_limits<result_type>::max(); }

 private:
  std::uint64_t state_;
};

/// Uniform double in [0, 1) with 53 random bits (any 64-bit generator).
template <typename Generator>
double UniformUnit(Generator& rng) {
  return static_cast<double>(rng() >> 11) * 0x1.0p-53;
}

/// The generator of item `index` of a seeded collection: independent streams, so
/// that items can be made on any thread in any order with the same result.
inline Rng TrajectoryRng(std::uint64_t seed, std::uint64_t index) {
  return Rng(SplitMix64Hash(SplitMix64Hash(seed) ^ index));
}

/// Uniform double in [lo, hi).
inline double Uniform(Rng& rng, double lo, double hi) { return lo + (hi - lo) * UniformUnit(rng); }

/// Standard normal sample (Box-Muller on two uniforms; one sample per call).
inline double StandardNormal(Rng& rng) {
  const double u1 = 1.0 - UniformUnit(rng);  // in (0, 1]
  const double u2 = UniformUnit(rng);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

/// z[0..n) = standard normals from Box-Muller pairs, both outputs used
/// (r cos a, r sin a with r = sqrt(-2 log u1), a = 2 pi u2); odd n drops the
/// last sine.
template <typename Generator>
void FillStandardNormal(Generator& rng, double* z, std::int64_t n) {
  for (std::int64_t i = 0; i < n; i += 2) {
    const double u1 = 1.0 - UniformUnit(rng);  // in (0, 1]
    const double u2 = UniformUnit(rng);
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double a = 2.0 * std::numbers::pi * u2;
    z[i] = r * std::cos(a);
    if (i + 1 < n) z[i + 1] = r * std::sin(a);
  }
}

/// Seeded Fisher-Yates shuffle of a random-access range.
template <typename It>
void Shuffle(It first, It last, Rng& rng) {
  const auto n = last - first;
  for (auto i = n - 1; i > 0; --i) {
    const auto j = static_cast<decltype(i)>(rng() % static_cast<std::uint64_t>(i + 1));
    std::swap(first[i], first[j]);
  }
}

}  // namespace diffdyn
