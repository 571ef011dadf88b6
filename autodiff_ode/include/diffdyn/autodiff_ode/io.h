// Atomic output files.
//
// Every output that others read (models, datasets, reports) is written to a
// temporary file beside the target and renamed into place, so a reader never
// sees half a file and a failed run leaves the old file untouched:
//
//   diffdyn::WriteFileAtomically("model.json", [&](std::ostream& out) {
//     out << json.dump();
//   });
#pragma once

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// Calls `write(stream)` on a temporary file next to `path`, then renames it to
/// `path`. Throws diffdyn::Error naming the path if the file cannot be written;
/// if `write` throws, the temporary file is removed and the exception passes on.
template <typename WriteFn>
void WriteFileAtomically(const std::filesystem::path& path, WriteFn&& write) {
  namespace fs = std::filesystem;
  const fs::path parent = path.has_parent_path() ? path.parent_path() : fs::path(".");
  DIFFDYN_CHECK(fs::is_directory(parent), path.string(), ": directory ", parent.string(),
                " does not exist");
  // Appended piecewise: g++ 12 reports a false -Wrestrict on "." + std::string&&.
  std::string tmp_name = ".";
  tmp_name += path.filename().string();
  tmp_name += ".tmp";
  const fs::path tmp = parent / tmp_name;
  try {
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      DIFFDYN_CHECK(out.good(), tmp.string(), ": cannot open for writing");
      write(out);
      out.flush();
      DIFFDYN_CHECK(out.good(), tmp.string(), ": write failed");
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    DIFFDYN_CHECK(!ec, path.string(), ": cannot rename into place: ", ec.message());
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

}  // namespace diffdyn
