# Two commands for a newcomer: `make demo` and `make test`.
# Both build their own virtual environment from the package index.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
# Workers for the test suite: both cores of a CI machine.
JOBS ?= 2

.PHONY: demo test lint bench clean derived docs

# setup.py builds DAQP's vendored sources at install: a change to them installs again.
$(STAMP): pyproject.toml setup.py $(wildcard src/equilibrist/native/daqp/src/*.c) \
          src/equilibrist/native/daqp_digest.c src/equilibrist/native/daqp_library.py
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "equilibrist needs Python 3.11 or newer")'
	$(PYTHON) -m venv $(VENV)
	@# uv installs the same packages from the same index several times faster than pip
	@# (27 s against 1.5-4 min here); pip stays in the environment for the user.
	@# Byte-compiled at install, as pip does and uv does not by default: where Python may not
	@# write its caches (PYTHONDONTWRITEBYTECODE), every process would otherwise compile
	@# sympy, scipy and the rest again (6 s of CPU before a plan, each time).
	$(PY) -m pip install --quiet uv
	@# The rl extra (in dev) brings PyPI's Linux PyTorch with its CUDA libraries (about 5 GB;
	@# its libraries link them, so they cannot be left out, and the CPU-only index is not
	@# PyPI): from a warm uv cache they are linked in seconds, byte-compiled in about 30 s.
	$(VENV)/bin/uv pip install --quiet --compile-bytecode --python $(PY) -e '.[dev]'
	@# PufferLib's vector interface, for envs/puffer.py's tests: pufferlib-core pins the PyTorch
	@# its CUDA extension was built for, which would replace the rl extra's; the modules used
	@# (vector, emulation) are plain Python, so it goes in without its pins (docs/envs.md).
	$(VENV)/bin/uv pip install --quiet --compile-bytecode --no-deps --python $(PY) 'pufferlib-core==3.0.23'
	$(PY) -m compileall -q src/equilibrist
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/equilibrist demo

# The type check (half a minute of one core from a fresh clone) runs beside the tests, in
# the cores' idle moments (the tests' subprocesses, browser and serial links wait); its
# report follows theirs, and either failing fails the target.
test: $(STAMP)
	$(VENV)/bin/ruff check src tests bench examples setup.py
	@# the layers of docs/architecture.md (pyproject.toml's [tool.importlinter])
	$(VENV)/bin/lint-imports --no-cache
	@$(VENV)/bin/mypy src/equilibrist > $(VENV)/mypy.log 2>&1 & types=$$!; \
	$(PY) -m pytest -n $(JOBS) -q --durations=15; tests=$$?; \
	wait $$types; typed=$$?; echo "mypy src/equilibrist:"; cat $(VENV)/mypy.log; \
	exit $$(( tests != 0 ? tests : typed ))

# The documentation site from docs/ and the tutorials (MkDocs, the API reference from the
# docstrings), warnings as errors, into build/site; tests/test_docs_site.py builds it too.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests bench examples setup.py
	$(VENV)/bin/lint-imports --no-cache
	$(VENV)/bin/mypy src/equilibrist

bench: $(STAMP)
	$(PY) bench/bench_cold.py
	$(PY) bench/bench_load.py
	$(PY) bench/bench_sim.py
	$(PY) bench/bench_playground.py
	$(PY) bench/bench_identify.py
	$(PY) bench/bench_sweep.py
	$(PY) bench/bench_envs.py
	$(PY) bench/bench_swingup.py
	$(PY) bench/bench_mpc.py
	$(PY) bench/bench_peers.py --only mpc
	$(PY) bench/bench_import.py
	$(PY) bench/bench_hil.py

# The catalogue's derived models shipped in the package (after changing a system,
# the mechanics layer or the code generation; a test says when it is due).
derived: $(STAMP)
	$(PY) -m equilibrist.numeric.package

clean:
	rm -rf $(VENV) report build
