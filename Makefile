# One-line set-up: every target creates the virtual environment it needs. Its packages are
# byte-compiled once, on every core, after install: where PYTHONDONTWRITEBYTECODE is set
# nothing is compiled on import, and each command would compile its imports again (3 s).
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# the runtime dependencies only (with the e57 extra): where make bench times the commands as
# fresh processes
RUN_VENV := .venv-run

.PHONY: demo test test-fast bench trust lint sample-data clean

# the report's browser test opens it in Debian's Chromium: installed here when it is missing and
# this machine lets make install it (root, with apt-get); otherwise the test names what to install
CHROMIUM := /usr/bin/chromium

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "$(PYTHON) not found (set PYTHON=...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --no-compile -e ".[dev]"
	$(BIN)/python -m compileall -q -j 0 $(VENV)/lib >/dev/null
	@touch $(STAMP)

$(CHROMIUM):
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing Debian's chromium for the report's browser test"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	else echo "$(CHROMIUM) missing: the browser test needs it (Debian: apt-get install chromium)"; fi

demo: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/ndt-register sample_data/scan_00.laz sample_data/scan_01.laz --out ndt_results/pair
	$(BIN)/python tools/demo_check.py pair ndt_results/pair sample_data/poses_T_world_scan.txt scan_00.laz scan_01.laz
	OPENBLAS_NUM_THREADS=1 $(BIN)/ndt-chain sample_data/*.laz --out ndt_results/chain --jobs 2
	$(BIN)/ndt-eval ndt_results/chain --gt sample_data/poses_T_world_scan.txt
	$(BIN)/ndt-export ndt_results/chain --out ndt_results/street.laz
	@echo "report: ndt_results/chain/report.html (open it in a browser); cloud: ndt_results/street.laz"

# two test processes, a test file each at a time (its module fixtures made once): many tests
# wait on processes they start, so two share the cores well even on a machine with two
test: $(STAMP) $(CHROMIUM)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=20

test-fast: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -m "not slow"

$(VENV)/.bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,bench]" || \
		echo "peers (open3d, small_gicp) not installed: the benchmark says so in their rows"
	@touch $(VENV)/.bench

$(RUN_VENV)/.installed: pyproject.toml Makefile
	$(PYTHON) -m venv $(RUN_VENV)
	$(RUN_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(RUN_VENV)/bin/python -m pip install --quiet --no-compile -e ".[e57]"
	$(RUN_VENV)/bin/python -m compileall -q -j 0 $(RUN_VENV)/lib >/dev/null
	@touch $(RUN_VENV)/.installed

bench: $(VENV)/.bench $(RUN_VENV)/.installed
	OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/run.py $(BENCH_ARGS)

# the trust sweep: every check's false alarms and misses on varied streets and real data
trust: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/trust_sweep.py $(TRUST_ARGS)

lint: $(STAMP)
	$(BIN)/ruff check ndt_cli tests tools benchmarks
	$(BIN)/ruff format --check ndt_cli tests tools benchmarks

sample-data: $(STAMP)
	$(BIN)/python tools/make_sample_data.py --out sample_data

clean:
	rm -rf $(VENV) $(RUN_VENV) ndt_results ndt_chain .pytest_cache
