# Compile options for the project's own targets. Nothing here is exported:
# installed targets carry only their include directories and dependencies.
#
# Warnings are shown everywhere and are errors only with DIFFDYN_STRICT=ON (the
# `strict` preset, CI's native build): a user's build never fails on a compiler's
# opinion. Third-party headers (Eigen, Ceres, Boost, ODE) come in as system headers
# through their imported targets, so their own code does not warn.
#
# One compiler bug is silenced, on every CPU: g++ before 13 reports
# -Wmaybe-uninitialized inside its own intrinsics headers (the self-initialised
# `__Y = __Y` of _mm256_undefined_pd, GCC PR 105593) wherever Eigen's AVX-512 code
# is inlined, despite their being system headers.
add_library(diffdyn_project_options INTERFACE)
set(DIFFDYN_GCC_PR105593 $<AND:$<CXX_COMPILER_ID:GNU>,$<VERSION_LESS:$<CXX_COMPILER_VERSION>,13>>)
target_compile_options(diffdyn_project_options INTERFACE
  -Wall -Wextra
  $<${DIFFDYN_GCC_PR105593}:-Wno-maybe-uninitialized>
  $<$<BOOL:${DIFFDYN_STRICT}>:-Werror>
  $<$<BOOL:${DIFFDYN_NATIVE}>:-march=native>
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined>)
target_link_options(diffdyn_project_options INTERFACE
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined>)

# diffdyn_use_project_options(target) gives a target the project's options.
function(diffdyn_use_project_options target)
  target_link_libraries(${target} PRIVATE $<BUILD_INTERFACE:diffdyn_project_options>)
endfunction()
