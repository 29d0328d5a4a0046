# hazardhunt: every target creates .venv and installs the project on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= demo-output
WORKERS ?= 2

.PHONY: install browser demo test test-slow test-all lint format type bench peers clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev,ros2]'
	touch $(STAMP)

install: $(STAMP)

APT_INSTALL := DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends

# Headless Chromium for tests/analysis/test_report_browser.py (Debian's package).
browser:
	@if command -v chromium >/dev/null 2>&1; then \
		exit 0; \
	elif [ "$$(id -u)" = 0 ]; then \
		apt-get update && $(APT_INSTALL) chromium; \
	elif command -v sudo >/dev/null 2>&1; then \
		sudo apt-get update && sudo $(APT_INSTALL) chromium; \
	else \
		echo "make browser: chromium is missing and this user can't install it." >&2; \
		echo "Install Debian's 'chromium' package as root:" >&2; \
		echo "  apt-get update && apt-get install -y --no-install-recommends chromium" >&2; \
		exit 1; \
	fi

# The quick campaign (campaigns/quick.toml) and its report; run it again to finish it.
demo: $(STAMP)
	$(BIN)/hazardhunt campaign campaigns/quick.toml --out $(OUT) --workers $(WORKERS)
	$(BIN)/hazardhunt report $(OUT)

test: $(STAMP) browser
	$(BIN)/pytest -q

test-slow: $(STAMP) browser
	$(BIN)/pytest -q -m slow

test-all: $(STAMP) browser
	$(BIN)/pytest -q -m 'slow or not slow'

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks scripts examples
	$(BIN)/ruff format --check src tests benchmarks scripts examples
	$(BIN)/python scripts/check_architecture.py

format: $(STAMP)
	$(BIN)/ruff format src tests benchmarks scripts examples
	$(BIN)/ruff check --fix src tests benchmarks scripts examples

type: $(STAMP)
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python benchmarks/throughput.py

# Off-the-shelf search methods beside hazardhunt's testers (benchmarks/peers/README.md), in
# their own venv: VerifAI's pins conflict with hazardhunt's.
PEERS_VENV ?= $(abspath ../peers-venv)
PEERS_STAMP := $(PEERS_VENV)/.installed
PEERS_ARGS ?=

$(PEERS_STAMP): benchmarks/peers/requirements.txt pyproject.toml
	$(PYTHON) -m venv $(PEERS_VENV)
	$(PEERS_VENV)/bin/pip install --quiet --upgrade pip
	$(PEERS_VENV)/bin/pip install --quiet -r benchmarks/peers/requirements.txt
	$(PEERS_VENV)/bin/pip install --quiet --no-deps -e .
	touch $(PEERS_STAMP)

peers: $(STAMP) $(PEERS_STAMP)
	$(PEERS_VENV)/bin/python benchmarks/peers/peers.py --hazardhunt $(BIN)/hazardhunt $(PEERS_ARGS)

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .mypy_cache .ruff_cache
