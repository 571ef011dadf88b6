// Shared by the fuzz targets: every diffdyn reader takes a path, so each input
// is written to a file in this process's own scratch folder first.
//
// A target passes when the reader either returns or throws diffdyn::Error (bad
// input, exit 2 at the command line); anything else that escapes (another
// exception, a crash, a sanitizer report, a hang past -timeout) is a finding.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace diffdyn::fuzz {

/// This process's scratch folder (created on first use).
inline const std::filesystem::path& ScratchFolder() {
  static const std::filesystem::path folder = [] {
    auto p = std::filesystem::temp_directory_path() / ("diffdyn-fuzz-" + std::to_string(getpid()));
    std::filesystem::create_directories(p);
    return p;
  }();
  return folder;
}

/// Writes `size` bytes at `data` to `path` (truncating it) and returns `path`.
inline std::string WriteBytes(const std::filesystem::path& path, const std::uint8_t* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path.string();
}

}  // namespace diffdyn::fuzz
