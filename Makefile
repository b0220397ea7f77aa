# The two commands a newcomer types (README.md):
#   make demo   set everything up (.venv) and run the main job: the paper's experiment in-process
#               (out/paper) and through the SITL, three cascades, recorded and analysed (out/demo),
#               then a 200-run Monte Carlo campaign of the +-30 % box (out/campaign)
#   make test   set everything up (.venv, test tools) and run lint, the docs' strict build and the test suite
#               (one pytest run, three workers over the 2 cores: pytest -n 3, CONTRIBUTING.md)
#   make docs   build the documentation site (out/site) with --strict: a broken link or reference fails
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

VIEW_VENDOR := gcs_scripts/view/static/vendor/MANIFEST.json

.PHONY: demo test paper lint docs bench clean view browser

$(STAMP): pyproject.toml setup.py
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,docs,campaign,cluster]'
	# MAVProxy without its GUI dependencies (wxPython, opencv, ...: ~1 GB); the tests drive it headless.
	$(BIN)/python -m pip install --quiet --no-deps 'MAVProxy>=1.8'
	@touch $(STAMP)

# MAVSDK-Python 3 (the gRPC API most PX4 users' scripts are written for) in a venv of its own: its
# mavsdk_server binary ships inside the PyPI wheel. tests/compat/test_mavsdk3.py runs it.
MAVSDK3 := .venv-mavsdk3/.installed
$(MAVSDK3):
	@test -x .venv-mavsdk3/bin/python || $(PYTHON) -m venv .venv-mavsdk3
	.venv-mavsdk3/bin/python -m pip install --quiet 'mavsdk==3.15.3'
	@touch $(MAVSDK3)

.PHONY: mavsdk3
mavsdk3 .venv-mavsdk3: $(MAVSDK3)

# The live view's JavaScript (three.js, uPlot): pinned in gcs_scripts/view/package-lock.json, fetched
# from the npm registry by `npm ci` once, then copied into static/vendor/; offline from then on.
$(VIEW_VENDOR): gcs_scripts/view/package.json gcs_scripts/view/package-lock.json gcs_scripts/view/build.py | $(STAMP)
	$(BIN)/python -m gcs_scripts.view.build

view: $(STAMP) $(VIEW_VENDOR)

# The view's browser tests drive Debian's Chromium through Playwright (never a downloaded browser).
browser:
	@command -v chromium >/dev/null || (apt-get update -qq && apt-get install -y -qq chromium)

demo: $(STAMP) $(VIEW_VENDOR)
	$(BIN)/quadsitl paper --out out/paper
	$(BIN)/quadsitl demo --out out/demo
	# Monte Carlo: the paper's +-30 % box, 200 runs x the three cascades (prints where the summary is)
	rm -rf out/campaign
	$(BIN)/quadsitl campaign paper_box --runs 200 --out out/campaign --no-progress

paper: $(STAMP)
	$(BIN)/quadsitl paper --out out/paper

lint: $(STAMP)
	$(BIN)/ruff check .

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

test: $(STAMP) $(VIEW_VENDOR) browser $(MAVSDK3)
	$(BIN)/ruff check .
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
	$(BIN)/python -m pytest -n 3

bench: $(STAMP)
	$(BIN)/python benchmarks/inprocess.py
	$(BIN)/python benchmarks/campaign.py

clean:
	rm -rf out .pytest_cache .ruff_cache
	find . -name __pycache__ -not -path './.venv*' -prune -exec rm -rf {} +
