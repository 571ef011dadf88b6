// Reading untrusted JSON: model files, --params files, system descriptions.
//
// Two rules keep a hostile or corrupt file from crashing or fooling a reader:
//
//   * nesting is limited before parsing (a file nested 100,000 deep would
//     otherwise exhaust the stack in the recursive code that walks it), and
//     the file's size is limited;
//   * integers are read with their range checked, never wrapped
//     (4294967304 is not 8).
//
//   nlohmann::json j = diffdyn::ReadJsonFile("model.json");
//   int hidden = diffdyn::JsonInt(j["hidden"], 1, 1 << 16, "architecture: 'hidden'");
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"

namespace diffdyn {

/// Deepest nesting of arrays and objects any diffdyn JSON input may have.
inline constexpr int kMaxJsonDepth = 64;
/// Largest JSON input (bytes) any diffdyn reader accepts.
inline constexpr std::uintmax_t kMaxJsonBytes = std::uintmax_t{1} << 30;

/// Parses `text` (named `name` in errors) after checking that arrays and objects
/// nest at most kMaxJsonDepth deep; throws diffdyn::Error "<name>: ..." (one
/// line) for invalid JSON or deeper nesting. `Json` is nlohmann::json, or
/// nlohmann::ordered_json where the order of an object's keys matters.
template <class Json = nlohmann::json>
Json ParseJsonText(std::string_view text, const std::string& name) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      DIFFDYN_CHECK(++depth <= kMaxJsonDepth, name, ": JSON nested deeper than ", kMaxJsonDepth, " levels");
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  try {
    return Json::parse(text);
  } catch (const typename Json::exception& e) {
    std::string what = e.what();
    for (char& c : what) {
      if (c == '\n' || c == '\r') c = ' ';
    }
    if (what.size() > 160) what = what.substr(0, 160) + "...";
    throw Error(StrCat(name, ": not valid JSON (truncated or corrupt?): ", what));
  }
}

/// Reads and parses the JSON file at `path` (a regular file of at most
/// kMaxJsonBytes); errors as ParseJsonText, naming the path.
template <class Json = nlohmann::json>
Json ReadJsonFile(const std::filesystem::path& path) {
  std::ifstream in = OpenInputFile(path);
  std::error_code ec;
  const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
  DIFFDYN_CHECK(!ec && bytes <= kMaxJsonBytes, path.string(), ": larger than ", kMaxJsonBytes, " bytes");
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  return ParseJsonText<Json>(text, path.string());
}

/// The integer `v` if it is one and lies in [lo, hi]; throws diffdyn::Error
/// "<what> must be an integer in [lo, hi]" otherwise.
inline long long JsonInt(const nlohmann::json& v, long long lo, long long hi, const std::string& what) {
  const bool in_range = v.is_number_integer() &&
                        (v.is_number_unsigned() ? v.get<unsigned long long>() <= static_cast<unsigned long long>(hi)
                                                : v.get<long long>() <= hi) &&
                        (v.is_number_unsigned() || v.get<long long>() >= lo);
  DIFFDYN_CHECK(in_range && v.get<long long>() >= lo, what, " must be an integer in [", lo, ", ", hi, "]");
  return v.get<long long>();
}

}  // namespace diffdyn
