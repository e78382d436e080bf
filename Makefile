# Two entry points (see README): `make demo` and `make test`. Both bootstrap .venv first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO_OUT ?= out/demo
PYTEST_ARGS ?=

.PHONY: demo test bootstrap syslibs clean benchmarks

bootstrap: $(STAMP)

# open3d links against the system library libusb-1.0: install it when we are root, else say what is missing.
syslibs:
	@if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	  echo "installing libusb-1.0-0 (needed by open3d) with apt-get"; \
	  (apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1 || (apt-get update -qq >/dev/null && apt-get install -y -qq libusb-1.0-0 >/dev/null)) \
	    || { echo "error: could not install libusb-1.0-0 with apt-get"; exit 1; }; \
	else echo "error: open3d needs the system library libusb-1.0: run 'sudo apt-get install libusb-1.0-0' and retry"; exit 1; fi

$(STAMP): pyproject.toml | syslibs
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || \
	  { echo "error: Python >= 3.11 is needed (found $$($(PYTHON) --version 2>&1)); set PYTHON=python3.11"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	@# byte-code for kinfu's own modules: where PYTHONDONTWRITEBYTECODE is set, Python would compile them from source
	@# in every command (0.1 s of each start-up); a stale .pyc after an edit is recompiled in memory, never trusted
	@$(BIN)/python -m compileall -q kinfu_cli >/dev/null
	@$(BIN)/python -m kinfu_cli.warmup || echo "warning: compiling the numba kernels ahead failed; the first runs compile them"
	@touch $(STAMP)

demo: bootstrap
	$(BIN)/python -m kinfu_cli.demo --data sample_data --out $(DEMO_OUT)

test: bootstrap
	$(BIN)/python -m pytest -n 2 -q $(PYTEST_ARGS)

# the [bench] extra (pyoctomap, a reference in bench_fusion.py) once; without a wheel for this machine the benchmark
# says so and runs the rest
$(VENV)/.bench-installed: $(STAMP)
	@$(BIN)/pip install --quiet -e '.[test,bench]' || echo "warning: the [bench] extra did not install; bench_fusion.py skips OctoMap"
	@touch $@

benchmarks: bootstrap $(VENV)/.bench-installed
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache
