# rfmap: set-up, tests and the Jupyter Book.
#   make install     create .venv, install torch (CPU, pinned) and the package with its dev, lab and geo extras, and
#                    register the project's Jupyter kernel (rfmap) in .venv
#   make test        unit tests, every notebook with nbval (through the rfmap kernel, from notebooks/, as
#                    JupyterLab runs it) and the book build (every notebook again, from a temporary directory), all
#                    at RFMAP_SCALE=ci, side by side (one thread each; logs in _build/test-logs)
#   make book        execute the notebooks at full scale and build the HTML book into _build/html; fail on an
#                    unresolved placeholder or a raw object repr on any page (scripts/book_text_check.py)
#   make book-check  screenshot every whole page of the built book; fail on error output or a missing or blank figure
#   make lab-check [NB=06_dem_deq_2d]
#                    open a chapter in JupyterLab (started by `make lab`) in headless Chromium, screenshot it into
#                    _build/screenshots; fail unless its kernel is "Python (rfmap)" and jupyterlab-myst renders its MyST
#   make chapter NB=06_dem_deq_2d [RFMAP_SCALE=ci|full]
#                    execute one chapter as the book does (rfmap kernel, same environment) into _build/chapters/,
#                    print its wall time and record it in _build/chapters/NB.time.json
#   make pages       regenerate the generated book pages (book/figures.md and the scoreboard of book/intro.md from
#                    src/rfmap/data/figures.json; book/design.md from src/rfmap/data/design.json; the retraining
#                    commands of book/reproduce.md from the shipped weights' metadata; the option tables of
#                    book/api/cli.md from the parsers of rfmap.cli)
#   make lab         start JupyterLab in the repository root with the book's environment (RFMAP_SCALE, default full)
#   make clean       remove build outputs (make distclean also removes .venv)

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TORCH := torch==2.13.0
RFMAP_SCALE ?= full
# environment of the notebook and book steps: VTK renders off-screen through EGL; the venv's scripts (rfmap) on PATH
NB_ENV := VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow PATH="$(CURDIR)/$(BIN):$$PATH"
BOOK_FLAGS := -W -n --keep-going --all
# the Jupyter kernel of .venv; it carries NB_ENV itself, so a chapter opened in any Jupyter front end runs as in the book
KERNEL := rfmap
LAB_FLAGS ?=
# nbval: a cell passes when it runs without error (outputs are not compared); every notebook runs through the project's
# kernel, which starts in notebooks/; a cell that runs for 20 minutes has hung
NBVAL_FLAGS := --nbval-lax --nbval-kernel-name $(KERNEL) --nbval-cell-timeout 1200 -p no:cacheprovider
# Jupyter refuses to run as root unless told to (containers often run as root)
LAB_ROOT := $(shell [ "$$(id -u)" = 0 ] && echo --allow-root)
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: install test book book-check lab-check chapter pages lab clean distclean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install $(TORCH)
	$(BIN)/python -m pip install -e ".[dev,lab,geo]"
	$(BIN)/python -m ipykernel install --sys-prefix --name $(KERNEL) --display-name "Python (rfmap)" \
		--env VTK_DEFAULT_OPENGL_WINDOW vtkEGLRenderWindow --env PATH '$(CURDIR)/$(BIN):$${PATH}'
	touch $@

# the three steps run side by side, one thread each; logs in _build/test-logs (scripts/run_tests.sh)
test: install
	scripts/run_tests.sh $(BIN) "$(NBVAL_FLAGS)" "$(BOOK_FLAGS)"

book: install
	$(NB_ENV) RFMAP_SCALE=$(RFMAP_SCALE) $(BIN)/jupyter-book build . $(BOOK_FLAGS)
	$(BIN)/python scripts/book_text_check.py --html _build/html
	@echo "book: open _build/html/index.html"

# one chapter, as the book runs it but from notebooks/ (as JupyterLab does); the executed copy keeps its outputs
chapter: install
	@test -n "$(NB)" || { echo "usage: make chapter NB=06_dem_deq_2d [RFMAP_SCALE=ci|full]" >&2; exit 2; }
	@test -f notebooks/$(NB).ipynb || { echo "no notebook notebooks/$(NB).ipynb" >&2; exit 2; }
	@mkdir -p _build/chapters
	@start=$$(date +%s.%N); \
	$(NB_ENV) RFMAP_SCALE=$(RFMAP_SCALE) $(BIN)/jupyter nbconvert --to notebook --execute notebooks/$(NB).ipynb \
		--ExecutePreprocessor.kernel_name=$(KERNEL) --ExecutePreprocessor.timeout=1800 \
		--ExecutePreprocessor.iopub_timeout=300 --ExecutePreprocessor.raise_on_iopub_timeout=True \
		--output-dir _build/chapters --output $(NB).ipynb; \
	end=$$(date +%s.%N); \
	$(BIN)/python scripts/chapter_times.py record $(NB) --start "$$start" --end "$$end" \
		--scale $(RFMAP_SCALE) --out _build/chapters/$(NB).time.json

pages: install
	$(BIN)/python scripts/make_figures_md.py
	$(BIN)/python scripts/make_design_md.py
	$(BIN)/python scripts/make_reproduce_md.py
	$(BIN)/python scripts/make_cli_md.py

lab: install
	$(NB_ENV) RFMAP_SCALE=$(RFMAP_SCALE) $(BIN)/jupyter lab --ServerApp.root_dir="$(CURDIR)" \
		--MappingKernelManager.default_kernel_name=$(KERNEL) $(LAB_ROOT) $(LAB_FLAGS)

book-check: install
	command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update && $(SUDO) apt-get install -y chromium; }
	$(BIN)/python scripts/book_check.py --html _build/html --out _build/screenshots

# the check starts `make lab` itself (same environment and kernel), with its own port, token and settings
lab-check: install
	command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update && $(SUDO) apt-get install -y chromium; }
	$(BIN)/python scripts/lab_check.py --notebook notebooks/$(or $(NB),06_dem_deq_2d).ipynb --out _build/screenshots

clean:
	rm -rf _build .pytest_cache .hypothesis
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +
	find . -path ./$(VENV) -prune -o -name .ipynb_checkpoints -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) src/*.egg-info
