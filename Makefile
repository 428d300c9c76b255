# raysweep — one plain GNU Makefile.
#   make            build build/bin/raysweepd
#   make test       build and run every test (SAN=1: ASan + UBSan build;
#                   TEST_JOBS=N programs at once, default twice the cores)
#   make bench      benchmarks, one JSON object per line
#   make test-cluster  replicas behind HAProxy/nginx, a Slurm job array, the
#                      container recipes (tests/cluster)
#   make run        start the daemon with the embedded default scene (PORT=8350)
#   make deps       install missing Debian packages for building and running
#                   (no-op when all present); deps-test adds the tests' tools,
#                   deps-cluster the balancers and Slurm, deps-bench haproxy
#                   for make bench (tools/deps.sh)
#   make install    raysweepd, raysweep, man pages, headers, libraysweep
#                   (PREFIX=/usr/local, DESTDIR= for staging)
#   make format     clang-format the C sources (tools/check-format.sh --fix)
# Variables: WERROR=1 adds -Werror; SAN=1 builds into build-san/;
# SIMD=generic builds the kernel as for a CPU other than x86 (the portable
# vector kernels alone, core/isa.h) into build-generic/ (build-san-generic/);
# make test-generic runs the kernel's SIMD tests on that build.
# On a machine without make or cc, ./make ARGS installs them and runs make ARGS.
# Every compile waits for `deps` (an order-only prerequisite), so make -jN
# never starts compiling before the packages are installed.

SHELL := /bin/bash
CC ?= cc

ifeq ($(SAN),1)
BUILD := build-san
SANFLAGS := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
OPT := -O1
else
BUILD := build
SANFLAGS :=
OPT := -O2
endif

ifeq ($(SIMD),generic)
BUILD := $(BUILD)-generic
SIMD_CPPFLAGS := -DRSW_SIMD_GENERIC_ONLY
else
SIMD_CPPFLAGS :=
endif

WARN := -Wall -Wextra -Wshadow -Wno-unused-parameter -Wstrict-prototypes
ifeq ($(WERROR),1)
WARN += -Werror
endif

# Each directory sees only the headers it may use: common/ (shared by the
# daemon and libraysweep) sees the public headers; the daemon sees
# common/ and server/; libraysweep and the CLI never see server/ (the CLI
# sees the public API, and common/ for its command-line tables, cmdline.h);
# tests see everything.
BASE_CPPFLAGS := -D_GNU_SOURCE -MMD -MP $(SIMD_CPPFLAGS)
CPPFLAGS := $(BASE_CPPFLAGS) -Iinclude -Icommon -Iserver
$(BUILD)/obj/common/%.o: CPPFLAGS := $(BASE_CPPFLAGS) -Iinclude -Icommon
$(BUILD)/obj/server/%.o: CPPFLAGS := $(BASE_CPPFLAGS) -Iinclude -Icommon -Iserver
$(BUILD)/obj/client/lib/%.o: CPPFLAGS := $(BASE_CPPFLAGS) -Iinclude -Icommon
$(BUILD)/obj/client/cli/%.o: CPPFLAGS := $(BASE_CPPFLAGS) -Iinclude -Icommon
CFLAGS := -std=c11 $(OPT) -g -fno-math-errno $(WARN) $(SANFLAGS) -fPIC
LDFLAGS := $(SANFLAGS)
# The volumetric path tracer's per-lane steps at -O3 (they inline into the
# wave's loop: the atmosphere bench renders ~4% faster). ISO C mode keeps
# every operation IEEE (no contraction, no reassociation): films are
# bitwise those of -O2.
VOLPATH_O3 := $(addprefix $(BUILD)/obj/server/kernel/,integrators/volpath.o media/layered.o media/media.o)
$(VOLPATH_O3): CFLAGS += -O3
# The surface path tracer's wave and its batched kernels at -O3 as well
# (the seed scene: 2-4% less CPU time; the same bitwise argument).
SEED_O3 := $(addprefix $(BUILD)/obj/server/kernel/,integrators/path.o hit.o render.o accel.o shapes/fill_simd.o \
             sensors/sensor_common.o samplers/independent.o samplers/pcg_simd.o simd/lanes_avx2.o \
             simd/lanes_avx512.o simd/lanes_sse2.o simd/lanes_generic.o bsdfs/roughconductor.o bsdfs/microfacet.o \
             emitters/directional.o emitters/area.o films/filter_gaussian.o core/vexp.o)
$(SEED_O3): CFLAGS += -O3
# And the rest of the kernel (not in the sanitizer build, which keeps -O1
# but for the files above): one-thread CPU time 0.979x the Cornell box,
# 0.990x the atmosphere, 1.002x the seed scene (9 alternating pairs each,
# 2026-11-29); films bitwise the same by the argument above (the 13
# reference films, the bundled jobs' hash).
ifneq ($(SAN),1)
KERNEL_O3 := $(patsubst %.c,$(BUILD)/obj/%.o,$(shell find server/kernel -name '*.c'))
$(KERNEL_O3): CFLAGS += -O3
endif
LIBS := -lembree3 -lOpenEXRCore -lnetcdf -lpng16 -ljpeg -lexpat -lcjson -lpthread -ldl -lm
DAEMON_LIBS := -lmicrohttpd -lcrypto
TEST_LIBS := -lcurl -lcrypto

# common/: the code the daemon and libraysweep share (status table and
# error records, SHA-256, the EXR writer and film attributes, the NetCDF
# dataset writer).
COMMON_SRC := $(sort $(wildcard common/*.c))
COMMON_OBJ := $(COMMON_SRC:%.c=$(BUILD)/obj/%.o)
COMMON_LIB := $(BUILD)/lib/librswcommon.a

KERNEL_SRC := $(shell find server/kernel -name '*.c' | sort)
KERNEL_OBJ := $(KERNEL_SRC:%.c=$(BUILD)/obj/%.o)
KERNEL_LIB := $(BUILD)/lib/librswkernel.a

SERVICE_SRC := $(shell find server/service -name '*.c' 2>/dev/null | sort)
SERVICE_OBJ := $(SERVICE_SRC:%.c=$(BUILD)/obj/%.o)
SERVICE_LIB := $(BUILD)/lib/librswservice.a
DAEMON_SRC := server/main.c $(shell find server/http -name '*.c' 2>/dev/null | sort) $(wildcard server/serve.c)
# The web viewer's files (ui/), compiled in as byte arrays by
# tools/embed-ui.sh; server/http/ui.c serves them. Every link of the HTTP
# objects links this one too.
UI_FILES := $(sort $(wildcard ui/*.html ui/*.js ui/*.css ui/*.svg ui/*.png))
UI_OBJ := $(BUILD)/obj/$(BUILD)/gen/ui_assets.o
DAEMON_OBJ := $(DAEMON_SRC:%.c=$(BUILD)/obj/%.o) $(BUILD)/obj/$(BUILD)/gen/default_scene.o $(UI_OBJ)

# failmalloc.c replaces malloc: only test_oom and raysweepd-failmalloc link it.
TEST_SUPPORT_SRC := $(filter-out tests/support/failmalloc.c,$(wildcard tests/support/*.c))
TEST_SUPPORT_OBJ := $(TEST_SUPPORT_SRC:%.c=$(BUILD)/obj/%.o)
# The test programs: every tests/**/test_*.c (tests/README.md: the folders
# mirror the code, tests/kernel/<class>/ the kernel's). A program is named
# after its file alone (BUILD/tests/test_NAME, wherever its folder), so two
# files of one name are an error. Those under tests/service, http, client
# and integration link the service library; the others the kernel alone.
TEST_SRC := $(sort $(shell find tests \( -path tests/support -o -path tests/fuzz -o -path tests/bench \
  -o -path tests/plugins -o -path tests/corpus -o -path tests/data \) -prune -o -name 'test_*.c' -print))
TEST_SERVICE_DIRS := tests/service tests/http tests/client tests/integration
TEST_SERVICE_SRC := $(filter $(TEST_SERVICE_DIRS:%=%/%),$(TEST_SRC))
TEST_KERNEL_SRC := $(filter-out $(TEST_SERVICE_SRC),$(TEST_SRC))
test_bin = $(patsubst %.c,$(BUILD)/tests/%,$(notdir $(1)))
TEST_BIN := $(call test_bin,$(TEST_SRC))
ifneq ($(words $(TEST_BIN)),$(words $(sort $(TEST_BIN))))
$(error two test programs share a name: $(shell printf '%s\n' $(notdir $(TEST_SRC)) | sort | uniq -d))
endif
# The object of test program NAME, wherever its source is.
test_obj = $(patsubst %.c,$(BUILD)/obj/%.o,$(filter %/$(1).c,$(TEST_SRC)))
TEST_SCRIPTS := $(sort $(wildcard tests/integration/test_*.sh))

# ---- fuzz harnesses (tests/fuzz): replayed in `make test`, fuzzed by `make fuzz`
# Each tests/fuzz/fuzz_NAME.c is built twice: with $(CC) and tests/fuzz/driver.c
# into $(BUILD)/tests/fuzz_NAME (replays tests/fuzz/corpus/NAME and
# tests/fuzz/crashes/NAME in make test), and with clang's libFuzzer into
# build-fuzz/bin/fuzz_NAME (make fuzz: each for FUZZ_SECONDS, FUZZ=NAME... for some).
FUZZ_SRC := $(sort $(wildcard tests/fuzz/fuzz_*.c))
FUZZ_NAMES := $(patsubst tests/fuzz/fuzz_%.c,%,$(FUZZ_SRC))
FUZZ_REPLAY := $(FUZZ_NAMES:%=$(BUILD)/tests/fuzz_%)
TEST_BIN += $(FUZZ_REPLAY)

# tests/bench/bench_*.c: one program each; the other .c files there are the
# benchmarks' shared code (accel_bench.c: the Embree ceilings), linked into each.
BENCH_SRC := $(wildcard tests/bench/bench_*.c)
BENCH_SUPPORT_OBJ := $(patsubst %.c,$(BUILD)/obj/%.o,$(filter-out $(BENCH_SRC),$(wildcard tests/bench/*.c)))
BENCH_BIN := $(patsubst %.c,$(BUILD)/bench/%,$(notdir $(BENCH_SRC)))
BENCH_SCRIPTS := $(sort $(wildcard tests/bench/bench_*.py))

# ---- libraysweep (client/lib): the C client library ------------------------
# libraysweep.a / .so link in common/ (the project's one EXR writer, the
# film attributes, the status tables, SHA-256) rather than copying them.
# The .so exports only the public API (client/lib/libraysweep.map).
CLIENT_SRC := $(sort $(wildcard client/lib/*.c))
CLIENT_OBJ := $(CLIENT_SRC:%.c=$(BUILD)/obj/%.o) $(COMMON_OBJ)
CLIENT_A := $(BUILD)/lib/libraysweep.a
CLIENT_SO := $(BUILD)/lib/libraysweep.so
CLIENT_PC := $(BUILD)/lib/pkgconfig/raysweep.pc
CLIENT_LIBS := -lcurl -lcjson -lexpat -lcrypto -lOpenEXRCore -lnetcdf -lpng16 -lpthread -lm
CLIENT_HEADERS := include/raysweep/client.h include/raysweep/status.h include/raysweep/version.h \
  include/raysweep/plugin.h
PREFIX ?= /usr/local
# The one version (include/raysweep/version.h), for raysweep.pc.
VERSION := $(shell sed -n 's/^\#define RSW_VERSION "\([^"]*\)"$$/\1/p' include/raysweep/version.h)
ifeq ($(VERSION),)
$(error cannot read RSW_VERSION from include/raysweep/version.h)
endif
MAN_PAGES := $(sort $(wildcard docs/man/*.1))
# raysweep.pc for a prefix ($(1)), as printf arguments, one line each.
client_pc_lines = 'prefix=$(1)' 'includedir=$${prefix}/include' 'libdir=$${prefix}/lib' '' \
  'Name: raysweep' 'Description: C client library for raysweepd, the raysweep radiometric kernel daemon' \
  'Version: $(VERSION)' 'Cflags: -I$${includedir}' \
  'Libs: -L$${libdir} -lraysweep' 'Libs.private: -lcurl -lcjson -lexpat -lcrypto -lOpenEXRCore -lnetcdf -lpng16 -lpthread -lm'

.PHONY: all deps deps-test deps-cluster deps-bench test bench run clean format install test-cluster test-generic
.SECONDARY:

all: deps $(BUILD)/bin/raysweepd $(CLIENT_A) $(CLIENT_SO) $(CLIENT_PC)

deps:
	@tools/deps.sh

# The tests' and the cluster tests' packages (tools/deps.sh sets), after
# the build set so two apt-gets never race under -jN.
deps-test: | deps
	@tools/deps.sh test

deps-cluster: | deps
	@tools/deps.sh cluster

deps-bench: | deps
	@tools/deps.sh bench

$(BUILD)/obj/%.o: %.c | deps
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) -c $< -o $@

$(KERNEL_LIB): $(KERNEL_OBJ)
	@mkdir -p $(dir $@)
	@rm -f $@ && ar rcs $@ $^

$(COMMON_LIB): $(COMMON_OBJ)
	@mkdir -p $(dir $@)
	@rm -f $@ && ar rcs $@ $^

$(SERVICE_LIB): $(SERVICE_OBJ)
	@mkdir -p $(dir $@)
	@rm -f $@ && ar rcs $@ $^

$(BUILD)/bin/raysweepd: $(DAEMON_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(DAEMON_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(DAEMON_LIBS)

# The embedded default scene (raysweepd serve without --scene): the XML as
# one C string literal (backslash, quote and '?' escaped: no trigraphs).
$(BUILD)/gen/default_scene.c: proto/examples/hdistant_seed.xml
	@mkdir -p $(dir $@)
	{ echo '#include "default_scene.h"'; echo 'const char rsw_default_scene_xml[] ='; \
	  sed -e 's/\\/\\\\/g' -e 's/"/\\"/g' -e 's/?/\\?/g' -e 's/^/  "/' -e 's/$$/\\n"/' $<; \
	  echo ';'; echo 'const size_t rsw_default_scene_xml_len = sizeof rsw_default_scene_xml - 1;'; } > $@

# (ui itself too: its time changes when a file is added or removed.)
$(BUILD)/gen/ui_assets.c: $(UI_FILES) ui tools/embed-ui.sh
	@mkdir -p $(dir $@)
	tools/embed-ui.sh $@ $(UI_FILES)

# ---- libraysweep rules ------------------------------------------------------
$(CLIENT_A): $(CLIENT_OBJ)
	@mkdir -p $(dir $@)
	@rm -f $@ && ar rcs $@ $^

$(CLIENT_SO): $(CLIENT_OBJ) client/lib/libraysweep.map
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -shared -Wl,-soname,libraysweep.so -Wl,--version-script=client/lib/libraysweep.map -o $@ $(CLIENT_OBJ) $(CLIENT_LIBS)

$(CLIENT_PC): include/raysweep/version.h
	@mkdir -p $(dir $@)
	printf '%s\n' $(call client_pc_lines,$(PREFIX)) > $@

# The client test sees only the public header and the static library.
$(BUILD)/tests/test_client: $(call test_obj,test_client) $(BUILD)/obj/tests/support/daemon.o $(CLIENT_A)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $< $(BUILD)/obj/tests/support/daemon.o $(CLIENT_A) $(CLIENT_LIBS)

# libraysweep's internals alone (client/lib/internal.h), no daemon; and
# its rsw_dataset with a film store (the EXRs made by common/film_io.c,
# which the library holds).
$(BUILD)/tests/test_spread $(BUILD)/tests/test_dataset_store: $(BUILD)/tests/%: $(BUILD)/obj/tests/client/%.o $(CLIENT_A)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $< $(CLIENT_A) $(CLIENT_LIBS)

# make install [PREFIX=/usr/local] [DESTDIR=staging root]: raysweepd and
# raysweep in bin/, their man pages in share/man/man1/, the client and
# plugin headers, libraysweep.{a,so} and raysweep.pc (whose prefix is
# PREFIX, not DESTDIR, for packaging).
install: $(BUILD)/bin/raysweepd $(BUILD)/bin/raysweep $(CLIENT_A) $(CLIENT_SO)
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/share/man/man1 \
	  $(DESTDIR)$(PREFIX)/include/raysweep $(DESTDIR)$(PREFIX)/lib/pkgconfig
	install -m 755 $(BUILD)/bin/raysweepd $(BUILD)/bin/raysweep $(DESTDIR)$(PREFIX)/bin/
	install -m 644 $(MAN_PAGES) $(DESTDIR)$(PREFIX)/share/man/man1/
	install -m 644 $(CLIENT_HEADERS) $(DESTDIR)$(PREFIX)/include/raysweep/
	install -m 644 $(CLIENT_A) $(DESTDIR)$(PREFIX)/lib/
	install -m 755 $(CLIENT_SO) $(DESTDIR)$(PREFIX)/lib/
	printf '%s\n' $(call client_pc_lines,$(PREFIX)) > $(DESTDIR)$(PREFIX)/lib/pkgconfig/raysweep.pc

# The HTTP encoders are not in the kernel library: link them in.
$(BUILD)/tests/test_http_encode: $(call test_obj,test_http_encode) $(BUILD)/obj/server/http/encode.o $(TEST_SUPPORT_OBJ) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(filter-out $(KERNEL_LIB) $(COMMON_LIB),$^) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS)

# test_oom fails each allocation in turn (tests/support/failmalloc.c, a
# build-time malloc hook: not instrumented itself; under SAN it forwards to
# ASan's allocator). It drives the HTTP layer in process, and spawns
# raysweepd-failmalloc (the daemon with the hook linked in).
FAILMALLOC_OBJ := $(BUILD)/obj/tests/support/failmalloc.o
$(FAILMALLOC_OBJ): tests/support/failmalloc.c | deps
	@mkdir -p $(dir $@)
	$(CC) -std=c11 -O2 -g -fPIC $(WARN) $(if $(filter 1,$(SAN)),-DFAILMALLOC_ASAN) -c $< -o $@
# The hook's definitions must be in the executable's dynamic symbol table
# for the libraries to bind to them (pthread_create is not referenced by a
# library the executable links directly: oneTBB's is found through Embree).
FAILMALLOC_LDFLAGS := -Wl,--export-dynamic-symbol=pthread_create -Wl,--export-dynamic-symbol='failmalloc_*'
HTTP_OBJ := $(patsubst %.c,$(BUILD)/obj/%.o,$(shell find server/http -name '*.c' 2>/dev/null | sort)) $(UI_OBJ)
# (libraysweep's own objects only: what it shares with the daemon comes
# from the common library.)
$(BUILD)/tests/test_oom: $(call test_obj,test_oom) $(FAILMALLOC_OBJ) $(HTTP_OBJ) $(CLIENT_SRC:%.c=$(BUILD)/obj/%.o) $(TEST_SUPPORT_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(FAILMALLOC_LDFLAGS) -o $@ $(filter %.o,$^) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(DAEMON_LIBS) $(TEST_LIBS)
$(BUILD)/tests/raysweepd-failmalloc: $(DAEMON_OBJ) $(FAILMALLOC_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(FAILMALLOC_LDFLAGS) -o $@ $(DAEMON_OBJ) $(FAILMALLOC_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(DAEMON_LIBS)

# test_image_exr_stress also reads every film through OpenEXR's C++ library
# (tests/support/imf_read.cpp), whose decoder is independent of OpenEXR Core.
IMF_CXXFLAGS := -std=c++17 $(OPT) -g -Wall -Wextra $(SANFLAGS) -I/usr/include/OpenEXR -I/usr/include/Imath -pthread
IMF_LIBS := -lOpenEXR -lIex -lIlmThread -lImath -pthread
$(BUILD)/obj/tests/support/imf_read.o: tests/support/imf_read.cpp tests/support/imf_read.h | deps
	@mkdir -p $(dir $@)
	$(CXX) $(IMF_CXXFLAGS) -c $< -o $@

$(BUILD)/tests/test_image_exr_stress: $(call test_obj,test_image_exr_stress) $(BUILD)/obj/tests/support/imf_read.o $(TEST_SUPPORT_OBJ) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CXX) $(LDFLAGS) -o $@ $(filter-out $(KERNEL_LIB) $(COMMON_LIB),$^) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(IMF_LIBS)

# Every other test program, by its link class: one rule each. (Each
# program's object is added as a prerequisite of its own.)
TEST_SPECIAL := test_client test_spread test_dataset_store test_http_encode test_oom test_image_exr_stress
$(foreach s,$(TEST_SRC),$(eval $(call test_bin,$(s)): $(patsubst %.c,$(BUILD)/obj/%.o,$(s))))

$(filter-out $(TEST_SPECIAL:%=$(BUILD)/tests/%),$(call test_bin,$(TEST_KERNEL_SRC))): $(TEST_SUPPORT_OBJ) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(filter %.o,$^) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS)

$(filter-out $(TEST_SPECIAL:%=$(BUILD)/tests/%),$(call test_bin,$(TEST_SERVICE_SRC))): $(TEST_SUPPORT_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(filter %.o,$^) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(TEST_LIBS) -lcrypto

$(BUILD)/bench/%: $(BUILD)/obj/tests/bench/%.o $(BENCH_SUPPORT_OBJ) $(TEST_SUPPORT_OBJ) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(filter-out $(KERNEL_LIB) $(COMMON_LIB),$^) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(TEST_LIBS)

# The test programs run in parallel, TEST_JOBS at a time (default: twice
# the number of cores; tests/run.sh says why, and which run alone). Everything a test's
# inner `make install` or `make run` needs is built first (the .so and .pc
# too), so concurrent inner makes find nothing to build.
TEST_JOBS :=
test: deps deps-test $(BUILD)/bin/raysweepd $(TEST_BIN) $(BUILD)/tests/raysweepd-failmalloc $(CLIENT_SO) $(CLIENT_PC)
	@RSW_BIN_DIR=$(BUILD)/bin BUILD=$(BUILD) SAN=$(SAN) TEST_JOBS=$(TEST_JOBS) RSW_TEST_TIMES=$(BUILD)/test-times \
	  tests/run.sh $(TEST_BIN) $(TEST_SCRIPTS)

# The kernel built as a CPU other than x86 builds it (SIMD=generic: the
# portable vector kernels alone, in build-generic/), and the tests of its
# batched kernels, ISA choice and wave determinism, and ocean_legacy's tables
# (its quadrature's scalar path alone there), run on it.
GENERIC_TESTS := test_simd test_isa test_wave test_eo_surfaces test_ocean_legacy
test-generic: deps
	$(MAKE) SIMD=generic $(addprefix build-generic/tests/,$(GENERIC_TESTS))
	@BUILD=build-generic tests/run.sh $(addprefix build-generic/tests/,$(GENERIC_TESTS))

bench: deps deps-bench $(BUILD)/bin/raysweepd $(BUILD)/bin/raysweep $(BENCH_BIN)
	@for b in $(BENCH_BIN); do $$b || exit 1; done
	@for s in $(BENCH_SCRIPTS); do RSW_BIN_DIR=$(BUILD)/bin $$s || exit 1; done

# make test-cluster: replicas behind real load balancers and schedulers
# (tests/cluster; the engines come from `make deps-cluster`). Also run by .ci/run.
# One at a time, as before parallel `make test`: each starts balancers or a
# Slurm cluster and kills replicas mid-sweep on a schedule of its own.
CLUSTER_SCRIPTS := $(sort $(wildcard tests/cluster/test_*.sh))
test-cluster: deps deps-cluster $(BUILD)/bin/raysweepd $(BUILD)/bin/raysweep
	@RSW_BIN_DIR=$(BUILD)/bin BUILD=$(BUILD) SAN=$(SAN) tests/run.sh -j 1 $(CLUSTER_SCRIPTS)

# make run PORT=N: another port. A port that is taken is said plainly, with
# a free one to try (bash's /dev/tcp: something answers there).
# (Only from the command line: a PORT in the environment is not ours.)
PORT := $(if $(filter command line,$(origin PORT)),$(PORT),8350)
run: deps $(BUILD)/bin/raysweepd
	@if (exec 3<>/dev/tcp/127.0.0.1/$(PORT)) 2>/dev/null; then \
	  p=$$(($(PORT) + 1)); while [ $$p -lt 65535 ] && (exec 3<>/dev/tcp/127.0.0.1/$$p) 2>/dev/null; do p=$$((p + 1)); done; \
	  echo "make run: port $(PORT) is in use (another raysweepd?): stop it, or try make run PORT=$$p" >&2; exit 1; \
	fi
	$(BUILD)/bin/raysweepd serve --listen 127.0.0.1:$(PORT)

format: deps deps-test
	tools/check-format.sh --fix

clean:
	rm -rf build build-san build-fuzz

# ---- raysweep CLI (client/cli): only the public libraysweep API ----
CLI_SRC := $(sort $(wildcard client/cli/*.c))
CLI_OBJ := $(CLI_SRC:%.c=$(BUILD)/obj/%.o)
CLI_LIBS := -lcurl -lcjson -lexpat -lcrypto -lOpenEXRCore -lnetcdf -lpng16 -lm -lpthread
.PHONY: cli-objs
all test: $(BUILD)/bin/raysweep
cli-objs: $(CLI_OBJ)
$(BUILD)/bin/raysweep: $(CLI_OBJ) $(BUILD)/lib/libraysweep.a
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(CLI_OBJ) $(BUILD)/lib/libraysweep.a $(CLI_LIBS)

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)

# ---- environment plugins (tests/plugins): the SDK examples, each built ----
# like a user would, against include/raysweep/plugin.h only (no kernel
# sources). Sanitizer builds load them uninstrumented.
PLUGIN_SRC := $(sort $(wildcard tests/plugins/*.c))
PLUGIN_SO := $(patsubst tests/plugins/%.c,$(BUILD)/plugins/%.so,$(PLUGIN_SRC))
PLUGIN_CFLAGS := -std=c11 -O2 -g $(WARN)
all test: $(PLUGIN_SO)
$(BUILD)/plugins/%.so: tests/plugins/%.c include/raysweep/plugin.h | deps
	@mkdir -p $(dir $@)
	$(CC) -shared -fPIC -I include $(PLUGIN_CFLAGS) -o $@ $< -lm

# ---- fuzzing (tests/fuzz, tests/fuzz/README.md) -----------------------------
# Replay builds: the harness, the standalone driver, and everything the
# daemon links but main.c and serve.c.
FUZZ_HTTP_OBJ := $(filter $(BUILD)/obj/server/http/%,$(DAEMON_OBJ)) $(UI_OBJ)
$(FUZZ_REPLAY): $(BUILD)/tests/fuzz_%: $(BUILD)/obj/tests/fuzz/fuzz_%.o $(BUILD)/obj/tests/fuzz/driver.o $(FUZZ_HTTP_OBJ) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $(filter-out $(KERNEL_LIB) $(SERVICE_LIB) $(COMMON_LIB),$^) $(SERVICE_LIB) $(KERNEL_LIB) $(COMMON_LIB) $(LIBS) $(DAEMON_LIBS)

# libFuzzer builds (clang 14): every source with ASan + UBSan and coverage.
FUZZ_CC ?= clang
FUZZ_SECONDS ?= 60
FUZZ ?= $(FUZZ_NAMES)
FUZZ_SAN := -fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer
FUZZ_CFLAGS := -std=c11 -O1 -g -fno-math-errno $(FUZZ_SAN) -fsanitize=fuzzer-no-link
FUZZ_LIB_SRC := $(KERNEL_SRC) $(SERVICE_SRC) $(COMMON_SRC) $(filter server/http/%,$(DAEMON_SRC)) $(BUILD)/gen/ui_assets.c
FUZZ_LIB_OBJ := $(FUZZ_LIB_SRC:%.c=build-fuzz/obj/%.o)
build-fuzz/obj/%.o: %.c | deps fuzz-check-cc
	@mkdir -p $(dir $@)
	$(FUZZ_CC) $(CPPFLAGS) $(FUZZ_CFLAGS) -c $< -o $@
build-fuzz/lib/libfuzzsrc.a: $(FUZZ_LIB_OBJ)
	@mkdir -p $(dir $@)
	@rm -f $@ && ar rcs $@ $^
build-fuzz/bin/fuzz_%: build-fuzz/obj/tests/fuzz/fuzz_%.o build-fuzz/lib/libfuzzsrc.a
	@mkdir -p $(dir $@)
	$(FUZZ_CC) $(FUZZ_SAN) -fsanitize=fuzzer -o $@ $< build-fuzz/lib/libfuzzsrc.a $(LIBS) $(DAEMON_LIBS)

.PHONY: fuzz fuzz-build fuzz-check-cc
fuzz-check-cc:
	@printf 'int LLVMFuzzerTestOneInput(const char *d, unsigned long n) { return 0; }\n' | \
	  $(FUZZ_CC) -x c - -fsanitize=fuzzer -o build-fuzz.check 2>/dev/null && rm -f build-fuzz.check || \
	  { rm -f build-fuzz.check; echo "make fuzz: needs $(FUZZ_CC) with libFuzzer (apt-get install clang libclang-rt-14-dev)" >&2; exit 1; }
fuzz-build: $(FUZZ:%=build-fuzz/bin/fuzz_%)
# clang and libFuzzer's runtime come from `tools/deps.sh fuzz` (Debian's
# clang, libclang-rt-14-dev), installed first when missing.
fuzz:
	@tools/deps.sh fuzz
	@$(MAKE) --no-print-directory fuzz-check-cc fuzz-build
	@tests/fuzz/run.sh $(FUZZ_SECONDS) $(FUZZ)
-include $(shell find build-fuzz/obj -name '*.d' 2>/dev/null)
