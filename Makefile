# Two entry points: `make run` (set up, then the whole pipeline) and `make test` (set up, then
# the test suite). Both create .venv on first use. torch is installed first and pinned: on the
# project's machines `torch==2.13.0` is a CPU wheel already on disk, whereas a looser requirement
# would make pip download a multi-GB CUDA build. Elsewhere, pyproject.toml accepts torch>=2.4.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TORCH ?= torch==2.13.0

.PHONY: setup run test lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet "$(TORCH)"
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $(STAMP)

# dvc runs each stage's `socnav-wm …` command, so the venv's bin goes first on PATH.
run: $(STAMP)
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/dvc repro

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest -n 2 -q

bench: $(STAMP)
	$(BIN)/socnav-wm bench env

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
