// Safe file input and atomic file output.
//
// Inputs are opened only when they are regular files: a FIFO, a device or a
// socket given as input could block forever or never end, so it is refused with
// one line naming the path:
//
//   std::ifstream in = diffdyn::OpenInputFile("data.csv");
//
// Every output that others read (models, datasets, reports) is written to a
// temporary file beside the target and renamed into place, so a reader never
// sees half a file and a failed run leaves the old file untouched. An existing
// target that is not a regular file (a device, a FIFO, a folder) is never
// replaced; a process interrupted while writing removes its temporary file
// (the command line's SIGINT/SIGTERM handler, through TemporaryFileInProgress):
//
//   diffdyn::WriteFileAtomically("model.json", [&](std::ostream& out) {
//     out << json.dump();
//   });
#pragma once

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <system_error>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// Throws diffdyn::Error "<path>: ..." unless `path` is an existing regular file
/// (or, with `allow_folder`, a folder). FIFOs, devices and sockets are refused.
inline void CheckInputPath(const std::filesystem::path& path, bool allow_folder = false) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  DIFFDYN_CHECK(fs::exists(status), path.string(), ": no such file");
  if (allow_folder && fs::is_directory(status)) return;
  DIFFDYN_CHECK(fs::is_regular_file(status), path.string(), ": not a regular file",
                allow_folder ? " or folder" : "", " (FIFOs, devices and sockets are refused)");
}

/// Throws diffdyn::Error "<path>: ..." if `path` exists and is not a regular
/// file (or, with `folder`, not a folder): outputs never replace devices,
/// FIFOs or folders.
inline void CheckOutputPath(const std::filesystem::path& path, bool folder = false) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status)) return;
  if (folder) {
    DIFFDYN_CHECK(fs::is_directory(status), path.string(), ": exists and is not a folder");
  } else {
    DIFFDYN_CHECK(fs::is_regular_file(status), path.string(),
                  ": exists and is not a regular file (refusing to replace it)");
  }
}

/// Opens the regular file `path` for reading (binary); throws diffdyn::Error
/// "<path>: ..." if it is missing, not a regular file or unreadable.
inline std::ifstream OpenInputFile(const std::filesystem::path& path) {
  CheckInputPath(path);
  std::ifstream in(path, std::ios::binary);
  DIFFDYN_CHECK(in.good(), path.string(), ": cannot open for reading");
  return in;
}

/// The temporary file WriteFileAtomically is writing now (nullptr if none), for a
/// signal handler to remove before the process ends (std::remove is not
/// async-signal-safe; ::unlink is).
inline std::atomic<const char*>& TemporaryFileInProgress() {
  static std::atomic<const char*> path{nullptr};
  return path;
}

/// Calls `write(stream)` on a temporary file next to `path`, then renames it to
/// `path`. Throws diffdyn::Error naming the path if the file cannot be written;
/// if `write` throws, the temporary file is removed and the exception passes on.
template <typename WriteFn>
void WriteFileAtomically(const std::filesystem::path& path, WriteFn&& write) {
  namespace fs = std::filesystem;
  const fs::path parent = path.has_parent_path() ? path.parent_path() : fs::path(".");
  DIFFDYN_CHECK(fs::is_directory(parent), path.string(), ": directory ", parent.string(),
                " does not exist");
  CheckOutputPath(path);
  // Appended piecewise: g++ 12 reports a false -Wrestrict on "." + std::string&&.
  std::string tmp_name = ".";
  tmp_name += path.filename().string();
  tmp_name += ".tmp";
  const fs::path tmp = parent / tmp_name;
  const std::string tmp_string = tmp.string();
  struct InProgress {  // published while the temporary file exists
    explicit InProgress(const char* p) { TemporaryFileInProgress().store(p); }
    ~InProgress() { TemporaryFileInProgress().store(nullptr); }
  } in_progress(tmp_string.c_str());
  try {
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      DIFFDYN_CHECK(out.good(), tmp.string(), ": cannot open for writing");
      write(out);
      out.flush();
      // A failed write (disk full) is a runtime failure, not bad input.
      if (!out.good()) throw std::runtime_error(StrCat(tmp.string(), ": write failed"));
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw std::runtime_error(StrCat(path.string(), ": cannot rename into place: ", ec.message()));
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

}  // namespace diffdyn
