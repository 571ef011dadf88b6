// printf-style formatting into a std::string, for reports whose number formats
// are printf's (the compiler checks the format against the arguments):
//
//   std::string row = diffdyn::StrPrintf("| %s | %.4g |", name.c_str(), value);
#pragma once

#include <cstdarg>
#include <cstdio>
#include <string>

namespace diffdyn {

/// The text printf(format, ...) would print.
[[gnu::format(printf, 1, 2)]] inline std::string StrPrintf(const char* format, ...) {
  va_list args;
  va_start(args, format);
  va_list count_args;
  va_copy(count_args, args);
  const int n = std::vsnprintf(nullptr, 0, format, count_args);
  va_end(count_args);
  std::string out(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(out.data(), out.size() + 1, format, args);
  va_end(args);
  return out;
}

}  // namespace diffdyn
