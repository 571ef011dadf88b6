# Compile options for the project's own targets. Nothing here is exported:
# installed targets carry only their include directories and dependencies.
add_library(diffdyn_project_options INTERFACE)
target_compile_options(diffdyn_project_options INTERFACE
  -Wall -Wextra -Werror
  # g++ 12 with AVX-512 reports false positives inside Eigen's vectorized code.
  -Wno-maybe-uninitialized
  $<$<BOOL:${DIFFDYN_NATIVE}>:-march=native>
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined>)
target_link_options(diffdyn_project_options INTERFACE
  $<$<BOOL:${DIFFDYN_SANITIZE}>:-fsanitize=address,undefined>)

# diffdyn_add_program(name SOURCES ...) builds an executable with the project's options.
function(diffdyn_use_project_options target)
  target_link_libraries(${target} PRIVATE $<BUILD_INTERFACE:diffdyn_project_options>)
endfunction()
