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
FRAGMENTS := src/amalgamate.sh src/manual.h src/internal.h src/impl_begin.h src/impl_end.h $(filter-out src/terrainnet.c,$(wildcard src/*.c))
# The implementation is compiled once per configuration, with TN_INTERNALS so that it exports the
# private code of the header's internals block, and linked. White-box tests and benches define
# TN_INTERNALS and link it too. A program that defines TERRAINNET_IMPLEMENTATION itself builds
# alone: only where it must compile the implementation differently, namely test_png and test_io
# (their own TN_MALLOC, counting allocations), test_robust (TN_MAX_ALLOC of 256 MiB) and
# test_bf16_amx (a model of the AMX tile unit in place of its intrinsics).
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
# the same drivers without libFuzzer: `make test` replays the committed corpus through each
FUZZ_REPLAY := $(patsubst tests/fuzz/%.c,build/test/fuzz/%,$(wildcard tests/fuzz/fuzz_*.c))

.PHONY: all header check-header check-single-header test check-compile check-layout demo demo-check bench fuzz clean mpi m32 studio studio-check
all: bin/terrainnet $(EXAMPLES) $(BENCHES)

header: terrainnet.h
terrainnet.h: $(FRAGMENTS)
	sh src/amalgamate.sh > $@.tmp && mv $@.tmp $@

# The committed header is exactly what src/ generates.
check-header:
	@sh src/amalgamate.sh | cmp -s - terrainnet.h && echo "check_header: 1 passed, 0 failed, 0 skipped" || \
	  { echo "FAIL check_header: terrainnet.h differs from src/ (run make header)"; echo "check_header: 0 passed, 1 failed, 0 skipped"; exit 1; }

$(LIB): src/terrainnet.c terrainnet.h | build
	$(CC) $(WARN) $(OPT) $(ARCH) $(CFLAGS) -DTN_INTERNALS -c $< -o $@

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

bin build build/test build/fuzz build/check build/test/fuzz:
	mkdir -p $@

# Tests run under AddressSanitizer + UndefinedBehaviorSanitizer.
$(LIB_SAN): src/terrainnet.c terrainnet.h | build
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -DTN_INTERNALS -c $< -o $@

# The tests with their own implementation do not wait for the shared one.
TESTS_SELF := $(patsubst tests/%.c,build/test/%,$(call SELF,$(wildcard tests/test_*.c)))
$(TESTS_SELF): build/test/%: tests/%.c terrainnet.h tests/tn_test.h | build/test
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -I. $< -o $@ $(LDLIBS)
$(filter-out $(TESTS_SELF),$(TESTS)): build/test/%: tests/%.c $(LIB_SAN) tests/tn_test.h | build/test
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -I. $< $(LIB_SAN) -o $@ $(LDLIBS)

# Each fuzz driver links the sanitised implementation (its own TERRAINNET_IMPLEMENTATION is for
# the standalone libFuzzer build). Run without arguments, each replays tests/fuzz/seeds and
# tests/fuzz/corpus/NAME.
build/test/fuzz/%: tests/fuzz/%.c tests/fuzz/fuzz_replay.h tests/fuzz/fuzz_files.h $(LIB_SAN) | build/test/fuzz
	$(CC) $(WARN) -O1 -g $(ARCH) $(SAN) $(CFLAGS) -DTN_FUZZ_MAIN -I. $< -DTN_IMPLEMENTATION_LINKED $(LIB_SAN) -o $@ $(LDLIBS)

# The header must compile warning-free as C99 with gcc and clang, as C++, and without threads.
check-compile: | build/check
	@sh tests/check_compile.sh

# Section layout of terrainnet.h (tests/check_layout.c); `make test` runs it inside test_layout.
check-layout: | build/check
	$(CC) $(WARN) -O1 $(CFLAGS) tests/check_layout.c -o build/check/check_layout
	./build/check/check_layout terrainnet.h
build/test/test_layout: tests/check_layout.c

# `make test` runs as jobs two at a time, even from a plain `make test`: first the two whole
# sanitised compiles of the implementation (the shared one and test_robust's own), side by side;
# then one `make -j2` of the rest, each job the build and the run of one test program or CLI
# script, or one check_compile configuration. A job writes the program's output, exit status and
# times to build/test/par/NAME.*; tests/run_tests.sh then reads them back in order and sums them.
# The jobs start in the order of RUNS, the longest first, so that the two slots finish together
# (build/test/times.txt after a run lists each job's CPU and wall seconds).
TEST_FIRST := test_gnn readme_runs test_cli test_style compile_portable test_bf16_amx test_world test_singan \
  test_png test_finedetail test_robust test_io test_season test_bf16 compile_gcc_c99 compile_no_threads \
  compile_no_tls compile_io_render test_gemm
TEST_NAMES = check_header $(addprefix compile_,$(shell sh tests/check_compile.sh --list)) test_cli readme_runs \
  $(notdir $(TESTS) $(FUZZ_REPLAY))
RUNS = $(addprefix build/test/par/,$(addsuffix .rc,$(TEST_FIRST) $(filter-out $(TEST_FIRST),$(TEST_NAMES))))
RUN = @sh tests/run_tests.sh --run
test: bin/terrainnet | build/check build/test build/test/fuzz
	@rm -rf build/test/par && mkdir -p build/test/par
	@$(MAKE) --no-print-directory -k -j2 $(LIB_SAN) build/test/test_robust || true
	@$(MAKE) --no-print-directory -k -j2 $(RUNS) || true
	@sh tests/run_tests.sh $(TEST_NAMES)
build/test/par/test_%.rc:
	@$(MAKE) --no-print-directory build/test/test_$*
	$(RUN) test_$* build/test/test_$*
build/test/par/fuzz_%.rc:
	@$(MAKE) --no-print-directory build/test/fuzz/fuzz_$*
	$(RUN) fuzz_$* build/test/fuzz/fuzz_$*
build/test/par/compile_%.rc:
	$(RUN) compile_$* env ARCH="$(ARCH)" sh tests/check_compile.sh $*
build/test/par/check_header.rc:
	$(RUN) check_header $(MAKE) --no-print-directory check-header
build/test/par/test_cli.rc:
	$(RUN) test_cli sh tests/test_cli.sh
build/test/par/readme_runs.rc:
	$(RUN) readme_runs sh tests/readme_runs.sh

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

# Fuzzing runs of every driver, FUZZ_SECONDS each, at the library's default limits (`make test`
# only replays the committed corpus). Needs clang with libFuzzer (Debian: clang, libclang-rt-14-dev).
# New inputs go to build/fuzz/corpus-NAME; tests/fuzz/corpus/NAME is the committed regression corpus.
# As in make test, every driver links the implementation instrumented once.
FUZZ_SECONDS ?= 30
FUZZ_CC   = clang -std=c99 -g -O1
LIB_FUZZ  = build/fuzz/terrainnet.o
$(LIB_FUZZ): src/terrainnet.c terrainnet.h | build/fuzz
	$(FUZZ_CC) -fsanitize=fuzzer-no-link,address,undefined -DTN_INTERNALS -c $< -o $@
build/fuzz/%: tests/fuzz/%.c tests/fuzz/fuzz_replay.h tests/fuzz/fuzz_files.h terrainnet.h $(LIB_FUZZ) | build/fuzz
	$(FUZZ_CC) -fsanitize=fuzzer,address,undefined -I. $< -DTN_IMPLEMENTATION_LINKED $(LIB_FUZZ) -o $@ -lm -pthread

fuzz: $(FUZZERS)
	@for f in $(FUZZERS); do n=$$(basename $$f); echo "== $$f ($(FUZZ_SECONDS) s)"; \
	  mkdir -p build/fuzz/corpus-$$n; \
	  ./$$f -max_total_time=$(FUZZ_SECONDS) -max_len=65536 build/fuzz/corpus-$$n tests/fuzz/seeds \
	    $$([ -d tests/fuzz/corpus/$$n ] && echo tests/fuzz/corpus/$$n) || exit 1; done

clean:
	rm -rf bin build

# 32-bit build (issue 35: wasm32 and -m32 have a 32-bit size_t): the implementation and a few
# tests with $(CC) -m32, no sanitizers. SSE arithmetic as on wasm32 and every 64-bit target: x87's
# excess precision (FLT_EVAL_METHOD 2) breaks the exact float round trips test_sketch checks.
# Skipped, saying so, when the compiler cannot target it (Debian: apt-get install gcc-multilib) or
# the machine cannot run what it builds (a kernel without IA-32 emulation).
M32      = -m32 -msse2 -mfpmath=sse
M32_TESTS = test_core test_noise test_image test_export test_tensor test_metrics test_sketch
m32: | build
	@if ! printf 'int main(void) { return 0; }\n' | $(CC) $(M32) -x c - -o build/m32_probe > /dev/null 2>&1; then \
	  echo "skipped m32: $(CC) -m32 cannot link (Debian: apt-get install gcc-multilib)"; echo "m32: 0 passed, 0 failed, 1 skipped"; exit 0; fi; \
	if ! ./build/m32_probe > /dev/null 2>&1; then \
	  echo "skipped m32: this machine cannot run 32-bit programs (a kernel without IA-32 emulation)"; echo "m32: 0 passed, 0 failed, 1 skipped"; exit 0; fi; \
	mkdir -p build/m32 build/test; \
	$(CC) $(M32) $(WARN) -O2 $(CFLAGS) -DTN_INTERNALS -c src/terrainnet.c -o build/m32/terrainnet.o || \
	  { echo "FAIL m32: the implementation does not compile"; echo "m32: 0 passed, 1 failed, 0 skipped"; exit 1; }; \
	pass=0; fail=0; for t in $(M32_TESTS); do \
	  if grep -q '^#define TERRAINNET_IMPLEMENTATION' tests/$$t.c; then lib=; else lib=build/m32/terrainnet.o; fi; \
	  if $(CC) $(M32) $(WARN) -O1 $(CFLAGS) -I. tests/$$t.c $$lib -o build/m32/$$t $(LDLIBS) && ./build/m32/$$t > build/m32/$$t.out 2>&1; \
	  then pass=$$((pass + 1)); tail -n 1 build/m32/$$t.out; \
	  else fail=$$((fail + 1)); echo "FAIL m32 $$t:"; grep FAIL build/m32/$$t.out | head -n 5; fi; done; \
	echo "m32: $$pass passed, $$fail failed, 0 skipped"; [ $$fail -eq 0 ]

# The studio (docs/studio.md): studio/studio.c and terrainnet.h compiled to WebAssembly with
# emscripten (Debian's 3.1.6: its optimiser needs the Debian node modules, NODE_PATH below),
# single-threaded, into studio/terrainnet.js + .wasm (committed, so the page works from any
# static server without a build), and the bundled styles copied from examples/data/styles/.
# Installs nothing: says what is missing. Always rebuilds (a fresh clone's file times say nothing).
EMCC ?= emcc
STUDIO_EMFLAGS = -std=c99 -Wall -Wextra -pedantic -O3 -msimd128 -DTN_NO_THREADS \
  -sMODULARIZE=1 -sEXPORT_NAME=createTerrainnet -sENVIRONMENT=web,worker -sALLOW_MEMORY_GROWTH=1 -sMAXIMUM_MEMORY=2GB \
  -sEXPORTED_RUNTIME_METHODS='["FS","ccall","UTF8ToString","HEAPF32","HEAPU8","HEAP32"]' -sEXPORTED_FUNCTIONS='["_malloc","_free"]'
studio:
	@command -v $(EMCC) > /dev/null 2>&1 || { echo "make studio: $(EMCC) not found (Debian: apt-get install emscripten)"; exit 1; }
	@[ -d /usr/share/nodejs ] || [ -n "$$NODE_PATH" ] || echo "make studio: no /usr/share/nodejs: emcc's optimiser may fail (Debian: apt-get install emscripten pulls the node modules)"
	NODE_PATH=$${NODE_PATH:-/usr/share/nodejs} $(EMCC) $(STUDIO_EMFLAGS) -I. studio/studio.c -o studio/terrainnet.js
	@rm -rf studio/styles && mkdir -p studio/styles && cp examples/data/styles/* studio/styles/
	@echo "make studio: studio/terrainnet.wasm $$(wc -c < studio/terrainnet.wasm) bytes, studio/terrainnet.js $$(wc -c < studio/terrainnet.js) bytes, $$(ls studio/styles/*.tnw | wc -l) styles; serve it: python3 -m http.server -d studio"

# index.html?selftest=1 in headless Chromium (studio/check.js, playwright-core from npm in
# build/pw): the bundled test sketch generated in WebAssembly against the native CLI's output
# stored beside its style. Fails unless the page writes "selftest: ok".
studio-check: studio
	@sh studio/check.sh
