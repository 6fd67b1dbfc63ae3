# drender — GNU Makefile. `make` builds ./build/drender, `make test` runs every
# test, `make bench` the benchmarks, `make sanitize` the tests under ASan/UBSan,
# `make fuzz` the libFuzzer targets of fuzz/ (clang; FUZZ_SECONDS each).
# Missing Debian packages are installed by scripts/install-deps.sh first.

PREFIX  ?= /usr/local
BUILD   ?= build
CC      ?= cc
CXX     ?= c++
# LTO inlines the small cross-module calls of the inner loop (~8% fewer instructions).
OPT     ?= -O3 -march=native -flto=auto
AR      := gcc-ar
SAN     ?=
PKGS    := OpenImageIO stb

ifeq ($(SAN),1)
OPT     := -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=undefined
endif

# -Wno-psabi: without AVX-512, GCC notes that core/simd.h's 64-byte vectors
# "change the ABI" when passed by value; they only ever go to static functions.
WARN     := -Wall -Wextra -Wpedantic -Wno-psabi
CPPFLAGS += -Icore -Iestimators -Idrivers -MMD -MP -DDR_DATADIR='"$(PREFIX)/share/drender"' -DDR_LIBDIR='"$(PREFIX)/lib/drender"'
# -fno-math-errno lets sqrt compile to one instruction; results are unchanged.
# -mmove-max/-mstore-max=256: GCC copies the eight-lane kernels' 192-byte
# vector triples (core/simd.h's dr_v3x8) with 256-bit moves in place instead
# of calling memcpy, which also spilled every vector register around the
# call: 4 % fewer instructions in a peer-box render, dr_path8_shade_lanes 19 %
# fewer (callgrind); the same bits. Only where the compiler knows the flags.
MOVE_MAX := $(shell $(CC) -mmove-max=256 -mstore-max=256 -E -x c /dev/null >/dev/null 2>&1 && \
                    echo -mmove-max=256 -mstore-max=256)
CFLAGS   += -std=c11 -D_GNU_SOURCE $(OPT) $(MOVE_MAX) $(WARN) -pthread -fno-math-errno
CXXFLAGS += -std=c++17 $(OPT) $(WARN) -pthread $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
# The drender binary does not link OpenImageIO: it loads $(PLUGIN) on first use
# (core/image_plugin.h says why). Tests, bench and fuzz programs link the
# image objects directly.
# -ldraco: KHR_draco_mesh_compression (core/draco_decode.cpp), -lmeshoptimizer:
# EXT_meshopt_compression (core/meshopt_decode.cpp), in every link of core/
HOST_LIBS := -ltinygltf -ldraco -lmeshoptimizer -lembree3 -lzstd -lz -lstdc++ -lm -pthread -ldl
# Deferred (=, not :=): on a fresh machine the packages are installed by the
# `deps` step, after make has read this file, so pkg-config must be asked when a
# link runs, not when the Makefile is parsed.
IMG_LIBS   = $(shell pkg-config --libs $(PKGS) 2>/dev/null)
LDLIBS   += $(IMG_LIBS) $(HOST_LIBS)
# (-Wno-psabi again: with -flto the code is generated at link time, which
# printed the same notes)
LDFLAGS  += $(OPT) $(MOVE_MAX) -Wno-psabi

# The image plugin's sources: the OpenImageIO shims, and the C its readers
# call before OpenImageIO sees a file (core/unsafe_images.h, core/bmp_check.h)
IMG_C    := core/bmp_check.c core/unsafe_images.c
CORE_C   := $(filter-out $(IMG_C),$(wildcard core/*.c estimators/*.c drivers/*.c))
IMG_CXX  := core/image_io.cpp core/vis.cpp
CORE_CXX := $(filter-out $(IMG_CXX),$(wildcard core/*.cpp))
CLI_C    := $(wildcard cli/*.c)
TEST_C   := $(wildcard tests/test_*.c)
BENCH_C  := $(wildcard bench/*.c)

CORE_OBJ := $(CORE_C:%.c=$(BUILD)/%.o) $(CORE_CXX:%.cpp=$(BUILD)/%.o)
CLI_OBJ  := $(CLI_C:%.c=$(BUILD)/%.o)
TEST_BIN := $(TEST_C:tests/%.c=$(BUILD)/tests/%)
BENCH_BIN:= $(BENCH_C:bench/%.c=$(BUILD)/bench/%)
LIB      := $(BUILD)/libdrender.a
IMG_OBJ  := $(IMG_CXX:%.cpp=$(BUILD)/%.o) $(IMG_C:%.c=$(BUILD)/%.o)
PLUGIN   := $(BUILD)/libdrender-image.so

.PHONY: all deps fuzz-deps demo test bench sanitize fuzz fuzz-build install clean sheen-table
all: deps $(BUILD)/drender $(PLUGIN)

# Installs missing system packages (fast no-op when all are present).
deps:
	@scripts/install-deps.sh

$(BUILD)/%.o: %.c | deps
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) -c $< -o $@
$(BUILD)/%.o: %.cpp | deps
	@mkdir -p $(dir $@)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

$(LIB): $(CORE_OBJ)
	@rm -f $@
	$(AR) rcs $@ $^

# -rdynamic: the plugin calls back into the binary (dr_set_error, dr_image_release).
# Under the sanitizers the image objects are linked in instead: GCC 12's
# LeakSanitizer misreads the dynamic TLS of libraries loaded by dlopen (glibc
# 2.36) and crashes at exit ("Tracer caught signal 11", DTLS at 0x1a16).
ifeq ($(SAN),1)
$(BUILD)/drender: $(CLI_OBJ) $(LIB) $(IMG_OBJ) | $(PLUGIN)
	$(CC) $(LDFLAGS) $(CLI_OBJ) $(IMG_OBJ) $(LIB) $(IMG_LIBS) $(HOST_LIBS) -o $@
else
$(BUILD)/drender: $(CLI_OBJ) $(LIB) | $(PLUGIN)
	$(CC) $(LDFLAGS) -rdynamic $(CLI_OBJ) $(LIB) $(HOST_LIBS) -o $@
endif
$(IMG_OBJ): CXXFLAGS += -fPIC
$(IMG_OBJ): CFLAGS += -fPIC
# The libraries most of the load's symbol bindings go to, named first so that
# the plugin's dlopen finds their symbols early in its search list: 167 ->
# 111 ms (scripts/image-lib-order.sh says why and measures the ranking).
# Deferred (=) for the reason IMG_LIBS is.
IMG_FIRST = $(shell scripts/image-lib-order.sh 2>/dev/null)
$(PLUGIN): $(IMG_OBJ) scripts/image-lib-order.sh
	$(CXX) $(LDFLAGS) -shared $(IMG_OBJ) -Wl,--push-state,--no-as-needed $(IMG_FIRST) -Wl,--pop-state $(IMG_LIBS) -o $@

$(BUILD)/tests/%: $(BUILD)/tests/%.o $(LIB) $(IMG_OBJ)
	$(CC) $(LDFLAGS) $< $(IMG_OBJ) $(LIB) $(LDLIBS) -o $@
# the fuzz corpus replay of the option parsers (tests/test_fuzz_cli.c) links cli/'s parsers
$(BUILD)/tests/test_fuzz_cli: $(BUILD)/tests/test_fuzz_cli.o $(BUILD)/cli/cli_util.o $(BUILD)/cli/grad_common.o \
		$(BUILD)/cli/mem_limits.o $(IMG_OBJ) $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS) -o $@
$(BUILD)/bench/%: $(BUILD)/bench/%.o $(LIB) $(IMG_OBJ)
	$(CC) $(LDFLAGS) $< $(IMG_OBJ) $(LIB) $(LDLIBS) -o $@
# The SoA floors' shading is plain loops that the compiler vectorises, and
# GCC's tuning for AVX-512 machines prefers 256-bit vectors for that: 8
# floats or 4 doubles to an instruction, where drender's explicit eight-lane
# doubles (core/simd.h) fill 512-bit registers. A floor must be the best such
# a design can do, so they are built for full registers (measured on the
# peer box: float 1.37-1.55 -> 1.16-1.32 s, double 1.65-1.79 -> 1.27-1.43 s;
# drender itself built so is no faster). Harmless without AVX-512. (Given
# at the link too: with LTO the code is generated there.)
FLOOR_VEC := $(shell $(CC) -mprefer-vector-width=512 -E -x c /dev/null >/dev/null 2>&1 && echo -mprefer-vector-width=512)
$(BUILD)/bench/soa_floor.o $(BUILD)/bench/soa_floor_%.o: CFLAGS += $(FLOOR_VEC)
$(BUILD)/bench/soa_floor $(BUILD)/bench/soa_floor_%: LDFLAGS += $(FLOOR_VEC)
# it measures loading the image library, so it must not link it (as drender does not)
$(BUILD)/bench/image_lib_rss: $(BUILD)/bench/image_lib_rss.o $(LIB)
	$(CC) $(LDFLAGS) -rdynamic $< $(LIB) $(HOST_LIBS) -o $@

# The allocation-failure injector of tests/cli_alloc_failures.sh, preloaded
# into drender: built without the sanitizers (under them it hands on to
# AddressSanitizer's allocator, tests/failalloc.c says how).
FAILALLOC := $(BUILD)/tests/libfailalloc.so
$(FAILALLOC): tests/failalloc.c tests/failalloc_new.cpp
	@mkdir -p $(dir $@)
	$(CC) -std=c11 -O2 $(WARN) -fPIC -c tests/failalloc.c -o $(BUILD)/tests/failalloc.o
	$(CXX) -std=c++17 -O2 $(WARN) -shared -fPIC $(BUILD)/tests/failalloc.o tests/failalloc_new.cpp -o $@ -ldl

# (the bench's programs are built too, not run: an interface they use that
# changed fails here, not at the next `make bench`)
test: deps $(BUILD)/drender $(TEST_BIN) $(BENCH_BIN) $(FAILALLOC)
	BUILD=$(BUILD) tests/run.sh

# The whole suite again under AddressSanitizer and UndefinedBehaviorSanitizer.
sanitize:
	ASAN_OPTIONS=fast_unwind_on_malloc=0 LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp \
		$(MAKE) test BUILD=build-san SAN=1

# ---- fuzzing (clang + libFuzzer; not needed by `make test`) ----
# Every core file plus the option parsers of cli/ is rebuilt with clang under
# -fsanitize=fuzzer-no-link,address,undefined into build-fuzz/, and tinygltf is
# compiled from its header (fuzz/tinygltf_impl.cpp) so that its parser is
# instrumented too (the shared libtinygltf is not). OpenImageIO, libpng & co.
# stay the uninstrumented system libraries. `make fuzz` runs each target for
# FUZZ_SECONDS from fuzz/corpus/TARGET (new inputs go to build-fuzz/corpus/).
FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?= gltf checkpoint cli image ktx2
FUZZ_BUILD   := build-fuzz
FUZZ_CC      ?= clang
FUZZ_CXX     ?= clang++
FUZZ_SAN     := -fsanitize=address,undefined -fno-sanitize-recover=undefined
FUZZ_CFLAGS  := -O1 -g -fno-omit-frame-pointer $(FUZZ_SAN) -fsanitize=fuzzer-no-link $(WARN)
FUZZ_CLI_C   := cli/cli_util.c cli/grad_common.c cli/mem_limits.c
FUZZ_OBJ     := $(CORE_C:%.c=$(FUZZ_BUILD)/%.o) $(CORE_CXX:%.cpp=$(FUZZ_BUILD)/%.o) $(IMG_CXX:%.cpp=$(FUZZ_BUILD)/%.o) \
                $(IMG_C:%.c=$(FUZZ_BUILD)/%.o) \
                $(FUZZ_CLI_C:%.c=$(FUZZ_BUILD)/%.o) $(FUZZ_BUILD)/fuzz/tinygltf_impl.o
FUZZ_BIN     := $(FUZZ_TARGETS:%=$(FUZZ_BUILD)/fuzz_%)
FUZZ_LIBS     = $(filter-out -ltinygltf,$(LDLIBS)) -lstb

fuzz-deps:
	@scripts/install-deps.sh --fuzz
$(FUZZ_BUILD)/%.o: %.c | fuzz-deps
	@mkdir -p $(dir $@)
	$(FUZZ_CC) $(CPPFLAGS) -Icli -std=c11 -D_GNU_SOURCE -pthread $(FUZZ_CFLAGS) -DDR_FUZZ_DATA='"$(CURDIR)/tests/data"' -c $< -o $@
$(FUZZ_BUILD)/%.o: %.cpp | fuzz-deps
	@mkdir -p $(dir $@)
	$(FUZZ_CXX) $(CPPFLAGS) -std=c++17 -pthread $(FUZZ_CFLAGS) $(shell pkg-config --cflags $(PKGS) 2>/dev/null) -c $< -o $@
$(FUZZ_BUILD)/fuzz_%: $(FUZZ_BUILD)/fuzz/fuzz_%.o $(FUZZ_OBJ)
	$(FUZZ_CXX) -fsanitize=fuzzer $(FUZZ_SAN) $^ $(FUZZ_LIBS) -o $@

fuzz-build: $(FUZZ_BIN)
fuzz: fuzz-build
	FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_BUILD=$(FUZZ_BUILD) fuzz/run.sh $(FUZZ_TARGETS)

bench: deps $(BUILD)/drender $(BENCH_BIN)
	BUILD=$(BUILD) bench/run.sh
	BUILD=$(BUILD) bench/grad.sh
	BUILD=$(BUILD) bench/sampling.sh
	BUILD=$(BUILD) bench/convergence.sh
	BUILD=$(BUILD) bench/media.sh

# The main job on the bundled scene: inverse rendering of the Cornell box
# (render a target, optimise wall colours and roughness from wrong values).
DEMO_OUT ?= out/demo
demo: all
	BUILD=$(BUILD) scripts/demo.sh $(DEMO_OUT)

# Regenerates core/sheen_albedo.c, the sheen lobe's albedo table
# (scripts/sheen_albedo_gen.c; a minute or two). Not part of the normal build.
sheen-table: scripts/sheen_albedo_gen.c core/sheen_albedo.h
	@mkdir -p $(BUILD)
	$(CC) -O2 -std=c11 -D_GNU_SOURCE $(WARN) -o $(BUILD)/sheen_albedo_gen scripts/sheen_albedo_gen.c -lm
	$(BUILD)/sheen_albedo_gen > core/sheen_albedo.c.tmp && mv core/sheen_albedo.c.tmp core/sheen_albedo.c

install: all
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/share/man/man1 $(DESTDIR)$(PREFIX)/share/drender/scenes
	install -d $(DESTDIR)$(PREFIX)/lib/drender
	install -m 755 $(BUILD)/drender $(DESTDIR)$(PREFIX)/bin/drender
	install -m 644 $(PLUGIN) $(DESTDIR)$(PREFIX)/lib/drender/
	install -m 644 man/drender.1 $(DESTDIR)$(PREFIX)/share/man/man1/drender.1
	install -m 644 scenes/cornell-box.gltf scenes/cornell-box.bin scenes/cornell-box-checker.png \
		$(DESTDIR)$(PREFIX)/share/drender/scenes/

clean:
	rm -rf build build-san build-fuzz build-narrow

-include $(shell find $(BUILD) $(FUZZ_BUILD) -name '*.d' 2>/dev/null)

# keep test/bench objects (chained implicit rules would delete them)
.SECONDARY:
