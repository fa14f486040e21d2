# terrainnet build. `make` builds the CLI, examples and benches into bin/; `make test` runs every test.
CC      ?= cc
CXX     ?= c++
ARCH    ?= -march=native
OPT     ?= -O2
WARN     = -std=c99 -Wall -Wextra -pedantic
CFLAGS  ?=
LDLIBS   = -lm -pthread
SAN      = -fsanitize=address,undefined,float-cast-overflow -fno-omit-frame-pointer -fno-sanitize-recover=undefined,float-cast-overflow

# world_mpi.c needs MPI: built by `make mpi` only
EXAMPLES := $(filter-out bin/world_mpi,$(patsubst examples/%.c,bin/%,$(wildcard examples/*.c)))
BENCHES  := $(patsubst bench/%.c,bin/%,$(wildcard bench/*.c))
TESTS    := $(patsubst tests/%.c,build/test/%,$(wildcard tests/test_*.c))
FUZZERS  := $(patsubst tests/fuzz/%.c,build/fuzz/%,$(wildcard tests/fuzz/fuzz_*.c))

.PHONY: all test check-compile check-layout demo demo-check bench fuzz clean mpi
all: bin/terrainnet $(EXAMPLES) $(BENCHES)

bin/terrainnet: examples/cli/terrainnet.c terrainnet.h | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. $< -o $@ $(LDLIBS)

bin/%: examples/%.c terrainnet.h | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. $< -o $@ $(LDLIBS)

bin/%: bench/%.c terrainnet.h | bin
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -I. $< -o $@ $(LDLIBS)

bin build/test build/fuzz build/check:
	mkdir -p $@

# Tests run under AddressSanitizer + UndefinedBehaviorSanitizer.
build/test/%: tests/%.c terrainnet.h tests/tn_test.h | build/test
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -I. $< -o $@ $(LDLIBS)

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
