# shapemotion — `make demo` and `make test` do their own set-up first; a second run installs nothing.
SHELL := /bin/bash
VENV  := .venv
PY    := $(VENV)/bin/python
STAMP := $(VENV)/.setup-done
# Debian packages the project needs: EGL/OSMesa for offscreen rendering, Chromium for browser tests.
APT_PACKAGES := libegl1 libgl1 libosmesa6 chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# The suite runs on one pytest-xdist worker per core, at most 4 (each worker loads its own Anny
# model; several tests start two processes of their own). A test file stays on one worker
# (--dist loadfile), so a module's fixtures are built once. TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); [ $$n -gt 4 ] && n=4; echo $$n)
PYTEST := $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

.PHONY: setup test test-fast demo bench docs clean

setup: $(STAMP)

$(STAMP): pyproject.toml Makefile $(wildcard package.json package-lock.json)
	@missing=$$(for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:" $$missing; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	@test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q -e '.[dev]'
	@if [ -f package-lock.json ]; then npm ci --no-audit --no-fund --loglevel=error; fi
	@touch $(STAMP)

test: setup
	$(PYTEST)

test-fast: setup
	$(PYTEST) -m "not slow"

demo: setup
	$(VENV)/bin/shapemotion demo --out demo_output

# The documentation site (mkdocs.yml) into site/; --strict turns any warning (a broken link or
# anchor, a page missing from the nav) into a failure. tests/test_docs.py runs the same build.
docs: setup
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

bench: setup
	@for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) demo_output .cache build site *.egg-info
