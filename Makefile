# The two commands: `make demo` and `make test`. Both create .venv and install what they need first:
# the demo only the runtime, the tests also the dev extras. uv (installed into the venv by pip) does the
# installing; UV=0 falls back to plain pip.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
UV ?= 1
RUNTIME := $(VENV)/.installed-runtime
DEV := $(VENV)/.installed-dev

ifeq ($(UV),1)
PIP_INSTALL = $(BIN)/uv pip install --quiet --python $(BIN)/python
else
PIP_INSTALL = $(BIN)/python -m pip install --quiet
endif

.PHONY: install install-dev test demo serve bench lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
ifeq ($(UV),1)
	$(BIN)/python -m pip install --quiet 'uv>=0.4'
endif

$(RUNTIME): pyproject.toml | $(BIN)/python
	$(PIP_INSTALL) -e .
	touch $@

# uv writes no bytecode; with PYTHONDONTWRITEBYTECODE nothing does, and every process of the suite would compile
# its imports afresh: tools/compile_imports.py compiles what they import (~13 s once)
$(DEV): pyproject.toml $(RUNTIME)
	$(PIP_INSTALL) -e '.[dev]'
	$(BIN)/python tools/compile_imports.py
	touch $@

install: $(RUNTIME)
install-dev: $(DEV)

lint: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/mypy app storage processing

# Test files are spread over TEST_WORKERS processes (a file stays on one worker: module fixtures are built once).
TEST_WORKERS ?= 3

# ruff first (a second); mypy (about a minute of CPU) runs beside the suite, whose workers often wait on
# servers and browsers; the target fails when either fails.
test: $(DEV)
	$(BIN)/ruff check .
	@$(BIN)/mypy app storage processing > $(VENV)/mypy.log 2>&1 & mypy=$$!; \
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --durations=25; tests=$$?; \
	wait $$mypy; types=$$?; echo "mypy app storage processing:"; cat $(VENV)/mypy.log; \
	test $$tests -eq 0 -a $$types -eq 0

demo: $(RUNTIME)
	$(BIN)/python -m app.demo

serve: $(RUNTIME)
	$(BIN)/attitude serve

bench: $(DEV)
	$(BIN)/python bench/ingest.py

clean:
	rm -rf $(VENV) var .pytest_cache .mypy_cache .ruff_cache
