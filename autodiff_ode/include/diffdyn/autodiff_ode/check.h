// Error checking for diffdyn.
//
// Two kinds of checks, following the convention of the whole library:
//
//   * Caller-facing checks (sizes, options, files) throw diffdyn::Error with a
//     message that names what was wrong and the values involved:
//
//       DIFFDYN_CHECK(x.size() == n, "state has ", x.size(),
//                     " entries, the system expects ", n);
//
//     The message parts are streamed with operator<<, so any printable value works.
//
//   * Internal invariants are DIFFDYN_DCHECK: checked in debug builds only.
//
// diffdyn::Error derives from std::runtime_error; the command line turns it into
// one line `error: ...` and exit code 2. diffdyn::NumericalError (step-size
// underflow, non-finite values, divergence) marks a runtime failure (exit 1).
#pragma once

#include <cassert>
#include <sstream>
#include <stdexcept>
#include <string>

namespace diffdyn {

/// A mistake of the caller: wrong sizes, bad options, unreadable files.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A numerical failure: non-finite values, step-size underflow, divergence.
class NumericalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Concatenates the printed forms of `parts` (each streamed with operator<<).
template <typename... Parts>
std::string StrCat(const Parts&... parts) {
  std::ostringstream out;
  out.precision(17);
  (out << ... << parts);
  return out.str();
}

}  // namespace diffdyn

/// Throws diffdyn::Error(StrCat(message parts...)) when `cond` is false.
#define DIFFDYN_CHECK(cond, ...)                                 \
  do {                                                           \
    if (!(cond)) throw ::diffdyn::Error(::diffdyn::StrCat(__VA_ARGS__)); \
  } while (false)

/// Debug-only check of an internal invariant.
#define DIFFDYN_DCHECK(cond) assert(cond)
