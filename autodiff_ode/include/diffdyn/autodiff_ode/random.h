// Seeded randomness.
//
// Every random thing in diffdyn takes a seed or a std::mt19937_64&; there is no
// std::random_device and no Eigen::Random. std::normal_distribution and friends
// are implementation-defined, so diffdyn draws its own from the raw 64-bit
// stream: the same seed gives the same numbers on every standard library.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace diffdyn {

/// The generator used everywhere.
using Rng = std::mt19937_64;

/// Uniform double in [0, 1) with 53 random bits.
inline double UniformUnit(Rng& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

/// Uniform double in [lo, hi).
inline double Uniform(Rng& rng, double lo, double hi) { return lo + (hi - lo) * UniformUnit(rng); }

/// Standard normal sample (Box-Muller on two uniforms; one sample per call).
inline double StandardNormal(Rng& rng) {
  const double u1 = 1.0 - UniformUnit(rng);  // in (0, 1]
  const double u2 = UniformUnit(rng);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
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
