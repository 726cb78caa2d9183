# make demo: clean a noisy capture with the shipped default cleaner.
# make test: ruff + pytest. Both create .venv when missing.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint venv clean-venv bench eval pairs

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[neural,onnx,fast,ui,pairs,dev]'
	touch $(STAMP)

# three.js for the HTML report: from the npm registry, pinned by package-lock.json, kept
# in node_modules/ (never committed). Without npm, `faceclean report` explains what to run.
NODE_STAMP := node_modules/.faceclean-installed

$(NODE_STAMP): package.json package-lock.json
	@if command -v npm >/dev/null; then npm ci --no-audit --no-fund && touch $(NODE_STAMP); \
	else echo "npm not found: faceclean report and its browser tests need node_modules/three"; fi

venv: $(STAMP) $(NODE_STAMP)

demo: $(STAMP) $(NODE_STAMP)
	$(BIN)/faceclean demo

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks

# one pytest worker per core (pytest-xdist): most cases run the CLI in a child process
test: $(STAMP) $(NODE_STAMP) lint
	$(BIN)/python -m pytest -n auto

bench: $(STAMP)
	$(BIN)/faceclean bench --openblas-core detect --json docs/benchmarks.json --markdown docs/BENCHMARKS.md

PAIRS ?= $(HOME)/.cache/faceclean/pairs

eval: $(STAMP)
	$(BIN)/faceclean eval --models benchmarks/models --json docs/results.json --markdown docs/RESULTS.md
	@if [ -d "$(PAIRS)" ]; then $(BIN)/faceclean eval --pairs $(PAIRS) --lstm --json docs/results_tracker.json --markdown docs/RESULTS.md; \
	else echo "no pairs in $(PAIRS): make pairs first for the MediaPipe table"; fi

# Rendered faces tracked by MediaPipe (hours on 2 cores; resumable, rerun to continue).
pairs: $(STAMP)
	$(BIN)/faceclean pairs --shared --synthetic 24 --held-out window --rom -o $(PAIRS) --jobs 2

clean-venv:
	rm -rf $(VENV)
