# Two commands do everything on a fresh machine (Python ≥ 3.11 with venv, and make):
#   make sim    set up .venv, fly the hardware-free simulation end to end (`sysid sim`)
#   make demo   set up .venv, identify the bundled example flight record, print the modes
#   make test   set up .venv, lint, run the test suite
PYTHON ?= python3
# One BLAS thread: the identification's matrices are small, and on two cores OpenBLAS's
# threads cost more than they give (measured: the case (a) benchmark identification takes
# 18 ms with one thread and 23-27 ms with two, with a second process running).
export OPENBLAS_NUM_THREADS ?= 1
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
BENCH_STAMP := $(VENV)/.installed-bench
FUZZ_STAMP := $(VENV)/.installed-fuzz

.PHONY: sim demo test test-loaded chromium bench bench-jsbsim bench-link bench-abort bench-agent bench-table soak fuzz screenshot examples clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# The peers (python-control, SIPPY) are only needed to benchmark against them.
$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $(BENCH_STAMP)

sim: $(STAMP)
	$(BIN)/sysid sim

demo: $(STAMP)
	$(BIN)/sysid identify examples/a2_lateral.csv --axes lateral

# The report test renders HTML in headless Chromium: Debian's package, installed when missing.
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
chromium:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	  { echo "installing Chromium (Debian package) for the report test"; \
	    $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq chromium >/dev/null; }

# `make test` runs the suite in two pytest-xdist processes (`TEST_WORKERS=0`: in one): most of
# its time is the simulated flights' and the radios' real time, so two workers finish it in
# about 10 min where one takes about 16.5 (measured here, 2026-11-27). A console snapshot that
# differed in two of three earlier two-worker runs has not since its screenshots wait for
# three frames alike (tests/ground/test_console_snapshots.py). `make test-loaded` keeps one
# process beside its two CPU hogs: two workers and two hogs on two cores failed five real-time
# tests, which is four busy processes on two cores, not the flight computer's load.
# The tests marked `alone` (tests/sim/test_sim_busy.py: five CPU hogs pinned beside its flight)
# run after the others, in their own session: beside a worker they starved its real-time tests
# (a recorder's sample ages past two periods) and their own flight (a 1.8 s gap in a sensor's
# stream; `make test` on 8128ca3, 2026-11-28).
TEST_WORKERS ?= 2
test: $(STAMP) chromium
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest -n $(TEST_WORKERS) --dist worksteal -m "not alone"
	$(BIN)/pytest -m alone

# The suite on a busy machine: `make test` with both cores loaded by two CPU hogs at normal
# priority, stopped when it ends (RUNS=3: three in a row, stopping at the first failure).
# RUNS is set per target: `make fuzz` has its own default, and a global `RUNS ?=` would
# give both targets whichever default came first.
test-loaded: RUNS ?= 1
test-loaded: $(STAMP)
	@$(PYTHON) -c "while 1: pass" & h1=$$!; $(PYTHON) -c "while 1: pass" & h2=$$!; \
	  trap 'kill $$h1 $$h2 2>/dev/null' EXIT; trap 'exit 130' INT TERM HUP PIPE; \
	  for k in $$(seq $(RUNS)); do echo "loaded run $$k of $(RUNS)"; $(MAKE) test TEST_WORKERS=0 || exit 1; done

bench: $(BENCH_STAMP)
	$(BIN)/python benchmarks/bench_identify.py

# Six JSBSim aircraft, calm, in light and in moderate turbulence, the full preset, a classic card
# and a sweep card, sized as the agent sizes them, with the vanes and the INS, the vanes alone
# and the INS alone, 10 seeds each, with the peers and the validated truth's Cramér–Rao bound
# on each row (about 46 minutes here;
# benchmarks/bench_jsbsim.py --quick reruns one row in about a minute).
bench-jsbsim: $(BENCH_STAMP)
	$(BIN)/python benchmarks/bench_jsbsim.py --bound

# Bytes on air and delivery time of a full-model result over the emulated radios.
bench-link: $(STAMP)
	$(BIN)/python benchmarks/bench_link.py

# Abort latency, switch low to trim on the MAVLink wire, over 30 drops mid-run.
bench-abort: $(STAMP)
	$(BIN)/python benchmarks/bench_abort.py --drops 30 --realtime 10

# The performance table (Markdown, with date, machine and commit; 20-25 minutes here):
# identification against the peers, loop lag at 100 and 400 Hz, CPU per component, bytes on
# air, abort latency. make bench-table ARGS=--quick for a shorter look.
bench-table: $(BENCH_STAMP)
	$(BIN)/python benchmarks/table.py $(ARGS)

# Coverage-guided fuzzing (atheris) of every parser: RUNS inputs per target, two targets at a
# time (RUNS=100000: 143 s here, two at a time; the default million takes about ten times as
# long; make fuzz RUNS=20000 for a quick look).
$(FUZZ_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,fuzz]'
	touch $(FUZZ_STAMP)

fuzz: RUNS ?= 1000000
fuzz: $(FUZZ_STAMP)
	$(BIN)/python fuzz/fuzz.py --runs $(RUNS)

# The agent's event-loop lag, CPU and memory over a simulated flight, in real time
# (45 minutes by default: make bench-agent MINUTES=5 for a quick look).
MINUTES ?= 45
bench-agent: $(STAMP)
	$(BIN)/python benchmarks/bench_agent.py --minutes $(MINUTES) --world-nice 10 --realtime 10

# The soak: the same flight for HOURS (default 2) in real time, an excitation a minute;
# the logs stay in soak-logs/ (replaced at each run), read period by period at the end.
HOURS ?= 2
soak: $(STAMP)
	rm -rf soak-logs
	$(BIN)/python benchmarks/bench_agent.py --minutes $$(( $(HOURS) * 60 )) --world-nice 10 \
	  --realtime 10 --keep soak-logs
	$(BIN)/python benchmarks/soak_report.py soak-logs

# The README's console picture, from a simulated flight flown from the console.
screenshot: $(STAMP)
	SAVE_SCREENSHOT=docs $(BIN)/pytest -q tests/sim/test_sim_console.py

examples: $(STAMP)
	$(BIN)/python examples/generate.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
