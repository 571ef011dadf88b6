// Fuzz target: the figures manifest reader (`diffdyn figures --manifest`) and, for
// every number of a manifest it accepts, its evaluation on a folder without CSVs.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "diffdyn/autodiff_ode/check.h"
#include "figures_page.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    for (const diffdyn::cli::FigureEntry& figure : diffdyn::cli::ParseFigureManifest(text, "figures.json")) {
      for (const diffdyn::cli::FigureNumber& number : figure.numbers) {
        (void)diffdyn::cli::Verdict(number, diffdyn::cli::EvaluateFigureNumber(number, "/nonexistent"));
      }
    }
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
