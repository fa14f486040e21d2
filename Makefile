# terrainnet build. `make` builds the CLI, examples and benches into bin/; `make test` runs every test.
CC      ?= cc
CXX     ?= c++
ARCH    ?= -march=native
OPT     ?= -O2
WARN     = -std=c99 -Wall -Wextra -pedantic
CFLAGS  ?=
LDLIBS   = -lm -pthread
SAN      = -fsanitize=address,undefined,float-cast-overflow -fno-omit-frame-pointer -fno-sanitize-recover=undefined,float-cast-overflow

# terrainnet.h is generated from src/ (src/amalgamate.sh); edit src/, then `make header`.
FRAGMENTS := src/amalgamate.sh src/manual.h src/impl_begin.h src/impl_end.h $(filter-out src/terrainnet.c,$(wildcard src/*.c))
# The implementation is compiled once per configuration and linked; a program that defines
# TERRAINNET_IMPLEMENTATION itself (white-box tests, which reach private tn__ code) builds alone.
LIB      = build/terrainnet.o
LIB_SAN  = build/terrainnet_san.o
SELF     = $(shell grep -l '^\#define TERRAINNET_IMPLEMENTATION' $(1))
# An example that compiles parts out (TN_NO_...) builds alone with its own configuration.
LINK_EX  = $(if $(shell grep -l '^\#define TN_NO_' $(1)),,-DTN_IMPLEMENTATION_LINKED $(LIB))

# world_mpi.c needs MPI: built by `make mpi` only
EXAMPLES := $(filter-out bin/world_mpi,$(patsubst examples/%.c,bin/%,$(wildcard examples/*.c)))
BENCHES  := $(patsubst bench/%.c,bin/%,$(wildcard bench/*.c))
TESTS    := $(patsubst tests/%.c,build/test/%,$(wildcard tests/test_*.c))
FUZZERS  := $(patsubst tests/fuzz/%.c,build/fuzz/%,$(wildcard tests/fuzz/fuzz_*.c))

.PHONY: all header check-header check-single-header test check-compile check-layout demo demo-check bench fuzz clean mpi
all: bin/terrainnet $(EXAMPLES) $(BENCHES)

header: terrainnet.h
terrainnet.h: $(FRAGMENTS)
	sh src/amalgamate.sh > $@.tmp && mv $@.tmp $@

# The committed header is exactly what src/ generates.
check-header:
	@sh src/amalgamate.sh | cmp -s - terrainnet.h && echo "check_header: 1 passed, 0 failed, 0 skipped" || \
	  { echo "FAIL check_header: terrainnet.h differs from src/ (run make header)"; echo "check_header: 0 passed, 1 failed, 0 skipped"; exit 1; }

$(LIB): src/terrainnet.c terrainnet.h | build
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -c $< -o $@

# Examples keep their own #define TERRAINNET_IMPLEMENTATION (each is a standalone program for
# `cc app.c -lm -pthread`); here they link the shared object instead.
bin/terrainnet: examples/cli/terrainnet.c $(LIB) | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -DTN_IMPLEMENTATION_LINKED -I. $< $(LIB) -o $@ $(LDLIBS)

bin/%: examples/%.c $(LIB) | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. $< $(call LINK_EX,$<) -o $@ $(LDLIBS)

bin/%: bench/%.c $(LIB) | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. $< $(if $(call SELF,$<),,$(LIB)) -o $@ $(LDLIBS)

# CI builds one example the single-header way, as a user would.
check-single-header: | build/check
	$(CC) $(WARN) $(OPT) -I. examples/render_terrain.c -o build/check/render_terrain_single -lm -pthread

bin build build/test build/fuzz build/check:
	mkdir -p $@

# Tests run under AddressSanitizer + UndefinedBehaviorSanitizer.
$(LIB_SAN): src/terrainnet.c terrainnet.h | build
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -c $< -o $@

build/test/%: tests/%.c $(LIB_SAN) tests/tn_test.h | build/test
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -I. $< $(if $(call SELF,$<),,$(LIB_SAN)) -o $@ $(LDLIBS)

# The header must compile warning-free as C99 with gcc and clang, as C++, and without threads.
check-compile: | build/check
	@sh tests/check_compile.sh

# Section layout of terrainnet.h (tests/check_layout.c); `make test` runs it inside test_layout.
check-layout: | build/check
	$(CC) $(WARN) -O1 $(CFLAGS) tests/check_layout.c -o build/check/check_layout
	./build/check/check_layout terrainnet.h
build/test/test_layout: tests/check_layout.c

# Test binaries build two at a time even from a plain `make test`: each is a full sanitised
# compile of the header, so a serial build would dominate the run.
test: bin/terrainnet | build/check build/test
	@$(MAKE) --no-print-directory -j2 $(TESTS)
	@sh tests/run_tests.sh $(TESTS)

# examples/world_mpi.c with OpenMPI (Debian: openmpi-bin libopenmpi-dev); skipped without mpicc.
MPICC ?= mpicc
mpi: | bin
	@if command -v $(MPICC) >/dev/null 2>&1; then \
	  echo "$(MPICC) ... examples/world_mpi.c -o bin/world_mpi"; \
	  $(MPICC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. examples/world_mpi.c -o bin/world_mpi $(LDLIBS); \
	else echo "make mpi: $(MPICC) not found (Debian: apt-get install openmpi-bin libopenmpi-dev); skipped"; fi

demo: bin/terrainnet
	@sh examples/demo.sh

# demo/index.html in headless Chromium (needs chromium; test_cli.sh runs it on a fast demo).
demo-check:
	@sh tests/demo_page.sh demo

bench: $(BENCHES)
	@for b in $(BENCHES); do echo "== $$b"; ./$$b; done

# Short fuzzing runs (not part of CI). Needs clang with libFuzzer (Debian: clang, libclang-rt-14-dev).
FUZZ_SECONDS ?= 30
build/fuzz/%: tests/fuzz/%.c terrainnet.h | build/fuzz
	clang -std=c99 -g -O1 -fsanitize=fuzzer,address,undefined -I. $< -o $@ -lm -pthread

fuzz: $(FUZZERS)
	@for f in $(FUZZERS); do echo "== $$f ($(FUZZ_SECONDS) s)"; \
	  mkdir -p build/fuzz/corpus-$$(basename $$f); \
	  ./$$f -max_total_time=$(FUZZ_SECONDS) -max_len=65536 build/fuzz/corpus-$$(basename $$f) tests/fuzz/seeds || exit 1; done

clean:
	rm -rf bin build
