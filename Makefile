# Two commands set up everything on a fresh machine:
#   make run   - serve the API (bootstraps .venv)
#   make test  - ruff, mypy and pytest (bootstraps .venv)
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
HOST ?= 127.0.0.1
PORT ?= 8000
PYTEST_ARGS ?=
# every install takes its versions from the checked-in lock (`make lock` regenerates it)
LOCK := requirements.lock
PIP := $(BIN)/python -m pip install -q -c $(LOCK)

.PHONY: venv run test lint typecheck pytest bench clean openapi load browser screenshot lock soak fuzz docker-dry

$(STAMP): pyproject.toml $(LOCK)
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(PIP) --upgrade pip
	$(PIP) -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	$(BIN)/python -m uvicorn service.app:app --host $(HOST) --port $(PORT)

lint: $(STAMP)
	$(BIN)/ruff check geometry solvers service tests bench

typecheck: $(STAMP)
	$(BIN)/mypy geometry solvers service

pytest: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 $(PYTEST_ARGS)

test: lint typecheck pytest

bench: $(STAMP)
	$(PIP) -e '.[bench]'
	$(BIN)/python -m bench.run_all

# regenerate requirements.lock: newest versions pyproject.toml allows, resolved in a fresh venv (CPython 3.11)
LOCK_VENV := .lock-venv
lock:
	rm -rf $(LOCK_VENV)
	$(PY) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install -q --upgrade pip
	$(LOCK_VENV)/bin/python -m pip install -q '.[dev,dask,bench]'
	{ echo "# Pinned versions of every dependency (all extras), resolved by 'make lock' with"; \
	  echo "# $$($(LOCK_VENV)/bin/python -c 'import platform; print(platform.python_implementation(), platform.python_version(), platform.machine())')."; \
	  echo "# Installs use it as a constraints file: pip install -c $(LOCK) -e '.[dev]'"; \
	  $(LOCK_VENV)/bin/python -m pip freeze --all --exclude-editable --exclude feedsched; } > $(LOCK).tmp
	mv $(LOCK).tmp $(LOCK)
	rm -rf $(LOCK_VENV) build

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache

openapi: $(STAMP)
	$(BIN)/python -m service.openapi_dump openapi/openapi.json

# 32 clients posting small toolpaths on loopback for DURATION s (starts its own server)
DURATION ?= 60
load: $(STAMP)
	$(BIN)/python -m bench.load --duration $(DURATION)

# 2 x the server's concurrency limit for SOAK_S s: the excess gets 503, RSS of server and workers sampled
SOAK_S ?= 600
soak: $(STAMP)
	$(BIN)/python -m bench.load --duration $(SOAK_S) --overload 2 --out bench/results/load_overload.json

# schemathesis: EXAMPLES generated cases per operation and mode against a real server (>= 1000 requests)
EXAMPLES ?= 80
fuzz: $(STAMP)
	$(BIN)/python -m bench.fuzz_api --examples $(EXAMPLES)

# headless Chromium for tests/service/test_browser.py: Debian's package (as root), never a browser download
browser:
	command -v chromium >/dev/null || { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium; }

# refresh the README's report screenshot (docs/report-flower.png) from the browser test
screenshot: $(STAMP)
	FEEDSCHED_REQUIRE_BROWSER=1 FEEDSCHED_SCREENSHOT=$(CURDIR)/docs/report-flower.png \
		$(BIN)/python -m pytest -q tests/service/test_browser.py

# the Dockerfile's steps without a Docker engine: COPY set, pip install, non-root CMD, HEALTHCHECK
docker-dry: $(STAMP)
	$(BIN)/python -m bench.docker_dry
