# diffdyn: the commands a newcomer runs.
#   make demo    install missing dependencies, build, run the main job
#   make test    install missing dependencies, build, run every test
#   make bench   benchmarks side by side with the PyTorch reference
BUILD_DIR ?= build
BUILD_TYPE ?= Release
NATIVE ?= ON
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=

.PHONY: all deps configure build test demo bench clean

all: build

deps:
	@scripts/install-deps

configure: deps
	@cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) -DDIFFDYN_NATIVE=$(NATIVE) \
	  $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	@cd $(BUILD_DIR) && ctest -j $(JOBS) --output-on-failure --timeout 900

demo: build
	@$(BUILD_DIR)/cli/diffdyn demo --out demo-output

bench: configure
	@scripts/install-deps --bench
	@cmake --build $(BUILD_DIR) -j $(JOBS)
	@BUILD_DIR=$(BUILD_DIR) scripts/run-bench

clean:
	@rm -rf $(BUILD_DIR)
