# phiscene: `make run` builds the default benchmark tables, `make test` runs the test suite, `make lint` the linters.
# Each creates the virtual environment (.venv) first if it is absent.

PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.phiscene-installed
JOBS ?= 2
TARGET ?= results/tables/phys.csv

.PHONY: run all test lint bench env clean

run: $(STAMP)
	$(BIN)/snakemake -j$(JOBS) $(TARGET)

all: $(STAMP)
	$(BIN)/snakemake -j$(JOBS)

# pytest-xdist runs the tests on $(JOBS) workers: 710 tests in 5 min 3 s on the 2-core machine (325f508 and its
# docs, a fresh clone; 6 min 33 s with the install; 711 tests in 8 min 37 s at 4f482ed on a slower day, 11 min 6 s
# with the install; 713 tests in 9 min 0 s at 69ca142, 10 min 15 s with the install, beside a 2-job workflow run;
# 718 tests in 5 min 21 s at 047fc2a in a fresh clone, 6 min 37 s with the install; 719 in 5 min 26 s at 3b26732,
# 6 min 48 s with the install; 732 in 4 min 23 s after the MuJoCo logging commit of stop 59, 5 min 21 s with it;
# 737 in 4 min 6 s at 2662a7b, 5 min 0 s with the install; 8 min 29 s at 58947fe beside a 2-job workflow run;
# 745 in 4 min 20 s at a018814 in a fresh clone, 5 min 15 s with the install; 746 in 4 min 26 s at cea3455, 5 min
# 26 s with the install; 750 in 11 min 50 s at 6f4b412 in a fresh clone beside a 2-job workflow run, 13 min 19 s
# with the install; 749 in 5 min 42 s at b958bdb in a fresh clone, 7 min 17 s with the install; 750 in 12 min 11 s
# at ef32b2f in a fresh clone beside a 2-job workflow run, 13 min 31 s with the install; 759 in 4 min 48 s at
# 61a757a in a fresh clone, 5 min 45 s with the install; 766 in 5 min 23 s at ddceaf4 in a fresh clone, 6 min 43 s
# with the install; 770 in 13 min 6 s at 10c4095 in a fresh clone beside a 2-job workflow run, 14 min 33 s with the
# install).
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS)

# ruff and snakefmt read their settings from pyproject.toml ([tool.ruff], [tool.snakefmt]).
LINT_PY := src tests workflow/scripts benchmarks tools
LINT_SMK := Snakefile workflow/rules

lint: $(STAMP)
	$(BIN)/ruff check $(LINT_PY)
	$(BIN)/snakefmt --check $(LINT_SMK)
	$(BIN)/snakemake --lint

bench: $(STAMP)
	$(BIN)/python benchmarks/default_run.py
	$(BIN)/python benchmarks/method_speed.py
	$(BIN)/python benchmarks/scaling.py

env: $(STAMP)

# torch is pinned (2.13.0): a CPU build lies on local disk, an unpinned torch pulls a multi-GB CUDA build.
$(STAMP): pyproject.toml
	tools/system-deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $@

clean:
	rm -rf results .snakemake
