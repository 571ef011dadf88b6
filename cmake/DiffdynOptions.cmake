# Compile options for the project's own targets. Nothing here is exported:
# installed targets carry only their include directories and dependencies.
#
# Warnings are shown everywhere and are errors only with DIFFDYN_STRICT=ON (the
# `strict` preset, CI's native build): a user's build never fails on a compiler's
# opinion. Third-party headers (Eigen, Ceres, Boost, ODE) come in as system headers
# through their imported targets, so their own code does not warn.
#
# g++ before 13 raises warnings from its middle end after inlining, whatever
# the headers' system status, that depend on the instruction set and the inlining
# and not on the code: -Wmaybe-uninitialized inside its own AVX-512 intrinsics (the
# self-initialised `__Y = __Y` of _mm256_undefined_pd, GCC PR 105593), and
# -Warray-bounds / -Wrestrict / -Wstringop-overflow / -Wstringop-overread on Eigen's
# vector loads of small fixed-size vectors and on std::string's copies once a
# concatenation is inlined into a large (unity) translation unit (GCC PRs 106247,
# 105329; char_traits::copy "specified bound exceeds maximum object size"). The
# first is off on every CPU; the others stay visible but do not fail the strict
# build. These are compiler-version rules, the same on every CPU.
add_library(diffdyn_project_options INTERFACE)
set(DIFFDYN_GCC12 $<AND:$<CXX_COMPILER_ID:GNU>,$<VERSION_LESS:$<CXX_COMPILER_VERSION>,13>>)
target_compile_options(diffdyn_project_options INTERFACE
  -Wall -Wextra
  $<${DIFFDYN_GCC12}:-Wno-maybe-uninitialized>
  $<$<BOOL:${DIFFDYN_STRICT}>:-Werror>
  $<$<AND:$<BOOL:${DIFFDYN_STRICT}>,${DIFFDYN_GCC12}>:-Wno-error=array-bounds -Wno-error=restrict
    -Wno-error=stringop-overflow -Wno-error=stringop-overread>
  $<$<BOOL:${DIFFDYN_NATIVE}>:-march=native>
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined>)
# The project's programs link with lld when the compiler accepts it (scripts/install-deps
# installs it): the test programs link several times faster than with GNU ld.
option(DIFFDYN_LLD "Link the project's programs with lld when available" ON)
if(DIFFDYN_LLD)
  include(CheckLinkerFlag)
  check_linker_flag(CXX -fuse-ld=lld DIFFDYN_HAVE_LLD)
endif()
target_link_options(diffdyn_project_options INTERFACE
  $<$<AND:$<BOOL:${DIFFDYN_LLD}>,$<BOOL:${DIFFDYN_HAVE_LLD}>>:-fuse-ld=lld>
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined>)

# diffdyn_use_project_options(target) gives a target the project's options. With
# DIFFDYN_FUZZ the compiled libraries (the code the fuzz targets reach, header-only
# parts included as they are instantiated there) carry libFuzzer's coverage
# instrumentation; test programs and tools do without it.
#
# With DIFFDYN_UNITY_BUILD (default ON) a multi-file target compiles its sources in
# batches of 8, one translation unit per batch: the shared templates (Eigen
# products, Jets, the models' engines) are instantiated and optimised once per
# batch instead of once per file. Names in a file's anonymous namespace must
# therefore be unique within its target. Developers editing one file at a time
# configure with -DDIFFDYN_UNITY_BUILD=OFF.
function(diffdyn_use_project_options target)
  target_link_libraries(${target} PRIVATE $<BUILD_INTERFACE:diffdyn_project_options>)
  get_target_property(type ${target} TYPE)
  get_target_property(sources ${target} SOURCES)
  list(LENGTH sources source_count)
  if(DIFFDYN_UNITY_BUILD AND source_count GREATER 1)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 8)
  endif()
  if(DIFFDYN_FUZZ AND type STREQUAL "STATIC_LIBRARY")
    target_compile_options(${target} PRIVATE -fsanitize=fuzzer-no-link)
  endif()
endfunction()

# diffdyn_precompile_headers(target [more headers]) precompiles the third-party
# headers every file of a multi-file target includes (Eigen, Ceres' Jet, odeint,
# nlohmann-json: about 8 s of parsing per file with g++ 12), once per target.
# Single-file programs share one per group (below). Nothing here is exported;
# DIFFDYN_PRECOMPILE_HEADERS=OFF compiles each file on its own includes.
function(diffdyn_precompile_headers target)
  if(DIFFDYN_PRECOMPILE_HEADERS)
    target_precompile_headers(${target} PRIVATE
      <algorithm> <cmath> <functional> <memory> <string> <vector>
      <Eigen/Dense> <ceres/jet.h> <boost/numeric/odeint.hpp> <nlohmann/json.hpp> ${ARGN})
  endif()
endfunction()

# diffdyn_share_program_headers(group target) gives a single-file program (an
# example, a figure, a benchmark, a fuzz target) the precompiled header of its
# group: the group's first program precompiles the third-party headers, the command
# line's and the learned models' header (with clang, their templates instantiated
# once), and every later program of the group reuses that one file. Programs of a
# group share their compile flags: each links the libraries whose usage requirements
# the header is compiled with (clang refuses a header built with other macros).
# Macros a program defines for itself (a figure's directory) are not used by those
# headers.
function(diffdyn_share_program_headers group target)
  if(NOT DIFFDYN_PRECOMPILE_HEADERS)
    return()
  endif()
  target_link_libraries(${target} PRIVATE diffdyn_solvers diffdyn_pusher fmt::fmt
    nlohmann_json::nlohmann_json CLI11::CLI11)
  get_property(owner GLOBAL PROPERTY DIFFDYN_PCH_OWNER_${group})
  if(owner)
    target_precompile_headers(${target} REUSE_FROM ${owner})
  else()
    diffdyn_precompile_headers(${target} <CLI/CLI.hpp> <fmt/core.h> <diffdyn/models/learned_model.h>)
    set_property(GLOBAL PROPERTY DIFFDYN_PCH_OWNER_${group} ${target})
  endif()
endfunction()
