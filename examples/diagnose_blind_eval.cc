// Blind evaluation of `diffdyn diagnose`: seeded hidden-effect cases on the
// pendulum, the cart-pole and the Panda, plus no-effect controls, each run
// through the full pipeline without knowing the truth. Prints one line per
// case and the scores of the acceptance criteria:
//   found   the right kind and joint named, magnitude within 15 %
//   exact   found and nothing else named
//   gain    heldout_sse_removed >= 0.5
//   control nothing named when nothing was hidden
//
//   example_diagnose_blind_eval [--cases 36] [--controls 6] [--seed 1000] [--quick]
#include <chrono>
#include <cstdlib>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <fmt/ranges.h>

#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/diagnosis.h"
#include "diffdyn/solvers/hidden_effects.h"

int main(int argc, char** argv) {
  using namespace diffdyn;
  int cases = 36, controls = 6;
  std::uint64_t seed = 1000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      cases = 2;
      controls = 1;
    } else if (a == "--cases" && i + 1 < argc) {
      cases = std::atoi(argv[++i]);
    } else if (a == "--controls" && i + 1 < argc) {
      controls = std::atoi(argv[++i]);
    } else if (a == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else {
      fmt::print(stderr, "error: unknown option {}\n", a);
      return 2;
    }
  }
  const std::vector<std::string> models = {"pendulum", "cartpole", "panda"};
  int found = 0, exact = 0, gain = 0, controls_clean = 0;
  double worst_seconds = 0;
  for (int i = 0; i < cases + controls; ++i) {
    const bool control = i >= cases;
    const std::string model = models[i % models.size()];
    HiddenEffectOptions options;
    if (model == "panda") options.duration = 12.0;
    const auto start = std::chrono::steady_clock::now();
    const HiddenEffectCase c = GenerateHiddenEffectCase(model, seed + i, control, options);
    const auto m = MakeAnalyticModel(model);
    const DiagnosisResult r = Diagnose(m, m->DefaultParams(), c.data, DiagnosisOptions{});
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    worst_seconds = std::max(worst_seconds, r.seconds);
    std::vector<std::string> labels;
    for (const Effect& e : r.named_effects) {
      labels.push_back(EffectLabel(e) + (e.params.empty() ? "" : fmt::format("={:.4g}", e.params[0])));
    }
    const std::string named = labels.empty() ? "-" : fmt::format("{}", fmt::join(labels, ", "));
    if (control) {
      const bool clean = r.named_effects.empty();
      controls_clean += clean;
      fmt::print("control  {:9s} seed {:5d}: named {:40s} {}  ({:.1f} s)\n", model, seed + i, named,
                 clean ? "OK" : "FALSE POSITIVE", seconds);
      continue;
    }
    double err = 0;
    const bool ok = MatchesHiddenEffect(model, c.effect, r.named_effects, 0.15, &err);
    found += ok;
    exact += ok && r.named_effects.size() == 1;
    gain += r.heldout_sse_removed >= 0.5;
    fmt::print("case     {:9s} seed {:5d}: hid {:14s}={:<10.4g} (x{:.1f} noise) named {:40s} err {:6.1f}% gain {:.3f} {}  ({:.1f} s)\n",
               model, seed + i, EffectLabel(c.effect), c.effect.params[0], c.ratio, named, 100 * err,
               r.heldout_sse_removed, ok ? "OK" : "MISS", seconds);
  }
  fmt::print("\nscores over {} hidden-effect cases and {} controls (seeds {}..{}):\n", cases, controls, seed,
             seed + cases + controls - 1);
  fmt::print("  found (kind, joint, magnitude within 15%): {}/{} = {:.1f}%\n", found, cases, 100.0 * found / std::max(1, cases));
  fmt::print("  found and nothing else named:              {}/{} = {:.1f}%\n", exact, cases, 100.0 * exact / std::max(1, cases));
  fmt::print("  heldout_sse_removed >= 0.5:                {}/{} = {:.1f}%\n", gain, cases, 100.0 * gain / std::max(1, cases));
  fmt::print("  controls with nothing named:               {}/{}\n", controls_clean, controls);
  fmt::print("  slowest diagnosis: {:.2f} s\n", worst_seconds);
  return 0;
}
