# Everything runs from a local virtual environment (.venv) installed from the pinned
# constraints file, so a fresh machine needs only Python 3.11 and pip.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install test test-fast docs demo bench lint clean

install: $(STAMP)

# PIP_CONSTRAINT also pins the isolated build environment (setuptools, wheel).
$(STAMP): pyproject.toml constraints.txt
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "husky-nav-sim needs Python >= 3.11, got " + sys.version.split()[0])'
	$(PYTHON) -m venv $(VENV)
	PIP_CONSTRAINT=$(CURDIR)/constraints.txt $(BIN)/python -m pip install --quiet --upgrade pip
	# PYTHONWARNINGS reaches the build backend: its editable-install notice is not the user's business
	PYTHONWARNINGS=ignore::UserWarning PIP_CONSTRAINT=$(CURDIR)/constraints.txt $(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

test: $(STAMP)
	$(BIN)/ruff check .
	$(MAKE) docs
	HUSKY_SIM_ALL_EXTRAS=1 $(BIN)/python -m pytest -n auto -q

# The documentation site (MkDocs, docs/ -> site/); --strict: a broken link or API reference fails.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

# The pure tests only (no PyBullet, no closed loop), in under a minute: for the edit-test cycle.
test-fast: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -n auto -q -m "not physics and not slow"

# The main job: the paper's point-stabilisation scenario and a head-on moving obstacle for the
# paper's bt, cbf and relax-cbf and our husky-cbf at N = 5 and 12 in PyBullet -> results table
# (with what each outcome means and why), per-run and comparison figures, and one MP4 per run.
DEMO_OUT := results/demo
DEMO_JOBS ?= 2

demo: $(STAMP)
	$(BIN)/husky-sim suite --scenarios paper_point_stabilisation head_on_moving_obstacle \
		--controllers bt cbf relax-cbf husky-cbf --horizons 5 12 --jobs $(DEMO_JOBS) --plots --out $(DEMO_OUT)
	for run in $(DEMO_OUT)/runs/*/; do $(BIN)/husky-sim render "$$run" || exit 1; done

bench: $(STAMP)
	mkdir -p results
	$(BIN)/husky-sim bench | tee results/bench.md

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

clean:
	rm -rf $(VENV) results .pytest_cache site
