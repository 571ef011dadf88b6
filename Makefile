# diffdyn: the commands a newcomer runs.
#   make demo        install missing dependencies, build, run the main job
#   make test        install missing dependencies, build, run every test
#   make test-quick  the same with the tests labelled `quick` only
#   make test-portable  clang++ at -O1, x86-64 baseline ISA (build-clang/), the quick
#                    tests (CI's portable stage)
#   make test-asan   clang++ ASan + UBSan build (preset debug-asan, build-asan/), the
#                    tests of autodiff_ode, models, physics and cli
#   make fuzz-quick  the same build, each libFuzzer target for 12 s (fuzz/README.md)
#   make bench       benchmarks side by side with the PyTorch reference
# Variables: BUILD_DIR (build), BUILD_TYPE (Release), NATIVE (ON: -march=native;
# OFF: the x86-64 baseline, for binaries that run on other machines), STRICT (OFF;
# ON turns warnings into errors, as CI does), CXX_COMPILER (CMake's default: g++),
# JOBS (all cores), CMAKE_FLAGS (more -D options).
BUILD_DIR ?= build
BUILD_TYPE ?= Release
NATIVE ?= ON
STRICT ?= OFF
CXX_COMPILER ?=
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
# A new build directory is generated for Ninja (it keeps both cores busy across
# targets); one configured earlier keeps its generator.
GENERATOR = $(if $(wildcard $(BUILD_DIR)/CMakeCache.txt),,-G Ninja)
# The test programs of the library's folders and the command line (test-asan).
ASAN_TESTS = autodiff_ode_tests models_tests physics_tests cli_tests

.PHONY: all deps configure build test test-quick test-portable test-asan fuzz-quick demo bench clean

all: build

deps:
	@scripts/install-deps

configure: deps
	@cmake -S . -B $(BUILD_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) -DDIFFDYN_NATIVE=$(NATIVE) \
	  -DDIFFDYN_STRICT=$(STRICT) $(if $(CXX_COMPILER),-DCMAKE_CXX_COMPILER=$(CXX_COMPILER)) \
	  $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	@cd $(BUILD_DIR) && ctest -j $(JOBS) --output-on-failure --timeout 900

test-quick: build
	@cd $(BUILD_DIR) && ctest -j $(JOBS) --output-on-failure --timeout 900 -L quick

test-portable:
	@$(MAKE) --no-print-directory test-quick BUILD_DIR=build-clang NATIVE=OFF CXX_COMPILER=clang++ \
	  CMAKE_FLAGS="-DDIFFDYN_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS_RELEASE='-O1 -DNDEBUG' $(CMAKE_FLAGS)"

test-asan:
	@scripts/install-deps --ci
	@cmake --preset debug-asan >/dev/null
	@cmake --build --preset debug-asan -j $(JOBS) --target $(ASAN_TESTS)
	@cd build-asan && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 \
	  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest -j $(JOBS) --output-on-failure --timeout 1800 -L '^(autodiff_ode|models|physics|cli)$$' -E '^(install\.|Demo\.|JointSpace\.EvalTakesDiagnoses)'

fuzz-quick:
	@scripts/install-deps --ci
	@cmake --preset debug-asan >/dev/null
	@cmake --build --preset debug-asan -j $(JOBS) --target fuzz_dataset fuzz_measured fuzz_model_file fuzz_params fuzz_options fuzz_sweep_spec fuzz_figure_manifest
	@ctest --test-dir build-asan -L fuzz -j $(JOBS) --output-on-failure

demo: build
	@$(BUILD_DIR)/cli/diffdyn demo --out demo-output

bench: configure
	@scripts/install-deps --bench
	@cmake --build $(BUILD_DIR) -j $(JOBS)
	@BUILD_DIR=$(BUILD_DIR) scripts/run-bench

clean:
	@rm -rf $(BUILD_DIR)
