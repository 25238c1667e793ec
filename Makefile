# The two commands of the README: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
# One venv, two stamps: `make demo` installs the core only (the simulator, its CLI, recordings);
# `make test` adds the dev tools and every extra (environments, figures, training: the CPU build
# of PyTorch, pinned in the train extra) to the same venv.
CORE := $(VENV)/.installed-core
DEV := $(VENV)/.installed-dev
STAMP := $(DEV)

.PHONY: demo test test-scale lint typecheck unit bench clean test-prereqs docs dist

$(CORE): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e .
	touch $(CORE)

$(DEV): $(CORE)
	$(BIN)/pip install -q -e '.[dev]'
	touch $(DEV)

demo: $(CORE)
	$(BIN)/plumeswarm demo

# A wheel and an sdist in dist/, checked by twine.
dist: $(DEV)
	rm -rf dist
	$(BIN)/python -m build --outdir dist . >/dev/null
	$(BIN)/twine check --strict dist/*
	@ls -l dist

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy
	$(BIN)/mypy examples

# Debian's chromium (browser test) and iproute2 (network-namespace test): installed only when
# missing and when root; otherwise those tests skip and say why.
test-prereqs:
	@missing=""; command -v chromium >/dev/null 2>&1 || missing="$$missing chromium"; \
	command -v ip >/dev/null 2>&1 || missing="$$missing iproute2"; \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing$$missing (Debian packages)"; \
		(apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing >/dev/null) \
			|| echo "could not install$$missing: their tests will skip"; \
	else echo "not root: not installing$$missing; their tests will skip"; fi

# The documentation site (mkdocs-material): site/; strict, so a broken link or a page missing from
# the navigation fails the build.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

# The 10-minute sim-time soak (tests/system/test_soak.py, marker soak) runs as its own, slower step.
test: $(STAMP) lint typecheck docs test-prereqs
	$(BIN)/python -m pytest -m "not soak and not scale"
	$(BIN)/python -m pytest -m soak -s

# The fault tests at 32 vehicles in 4 autopilot processes of 8 (marker scale: the router kill in
# both layouts, the lockstep partitions; root for the partitions): minutes each, not in `make test`.
test-scale: $(STAMP) test-prereqs
	$(BIN)/python -m pytest -m scale -s

bench: $(STAMP)
	$(BIN)/python -m plumeswarm.bench

clean:
	rm -rf $(VENV) dist build .pytest_cache .mypy_cache .ruff_cache site
