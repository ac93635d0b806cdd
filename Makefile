# Three entry points: `make models` (set up, then check the shipped trained models), `make run`
# (set up, then the whole pipeline) and `make test` (set up, then the test suite). Each creates
# .venv on first use. torch is installed first and pinned: on the project's machines
# `torch==2.13.0` is a CPU wheel already on disk, whereas a looser requirement would make pip
# download a multi-GB CUDA build. Elsewhere, pyproject.toml accepts torch>=2.4.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TORCH ?= torch==2.13.0

# `make run`'s parallel agent trainings: JOBS `dvc repro` processes at once, THREADS torch threads
# each (by default one job per core, one thread per job).
CORES := $(shell getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
JOBS ?= $(CORES)
THREADS ?= $(shell j=$(JOBS); t=$$(( $(CORES) / (j > 0 ? j : 1) )); echo $$(( t > 0 ? t : 1 )))

.PHONY: setup models run repro study scenarios test lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet "$(TORCH)"
	$(BIN)/pip install --quiet -e ".[pipeline,sweep,dev]"
	touch $(STAMP)

# The trained models a clone ships, without training: git tracks models/ (dvc.yaml's outputs
# with `cache: false`; data/ stays in DVC's cache). `socnav-wm models` loads each, compares it
# with dvc.lock and says what `dvc status` says; exit status 1 when one is missing or broken.
models: $(STAMP)
	$(BIN)/socnav-wm models

# dvc runs each stage's `socnav-wm …` command, so the venv's bin goes first on PATH.
# The last line says how long the whole job took (set-up included).
run:
	@start=$$(date +%s); \
	$(MAKE) $(STAMP) && PATH="$(CURDIR)/$(BIN):$$PATH" $(MAKE) repro; status=$$?; \
	elapsed=$$(( $$(date +%s) - start )); \
	echo "make run: exit status $$status after $$((elapsed / 60)) min $$((elapsed % 60)) s"; \
	exit $$status

# `dvc repro` with the agent trainings and the evaluations in parallel (with whatever `dvc` is
# on PATH). DVC runs one stage at a time, and the trainings (the agents and the planning models:
# independent stages, minutes each on one core) are most of the pipeline's time, so they run
# first as JOBS `dvc repro --single-item` processes, one per line of stage names: DVC releases
# its repository lock while a stage's command runs, and --wait-for-lock queues the jobs' short
# bookkeeping (hashing, dvc.lock). The two long planner evaluations start first:
# vae-lstm-mpc's (it needs only the world model), and wm-mpc's on the same line as the planning
# model it plans with (seed 0), so that it runs after it. The world-model variants follow, the
# longest trainings; the dueling-dqn ones fill the end, so that the last job to finish is a
# short one. The other evaluations follow the same way, and the final `dvc repro` runs the rest
# (the report) and finds everything else up to date. A training's numbers do not depend on the order; the
# world-model variants' can differ in the last bits with THREADS (float32 sums), and dvc.lock's
# were made with THREADS=1. JOBS=1 gives the plain sequential `dvc repro report`. The studies
# (studies/dvc.yaml: grids of agent runs, hours on two cores) are not part of it.
PARALLEL = OMP_NUM_THREADS=$(THREADS) xargs -L 1 -P $(JOBS) dvc --wait-for-lock repro --single-item

repro:
	dvc repro train_lstm
	dvc stage list --name-only \
		| grep -E '^(train_planning_model@|train_agent@|evaluate_vae_lstm_mpc$$)' \
		| awk '/^evaluate_vae_lstm_mpc$$/ { first = first $$0 "\n"; next } \
			/^train_planning_model@0$$/ { first = first $$0 " evaluate_wm_mpc\n"; next } \
			/@dueling-dqn-/ { short = short $$0 "\n"; next } { rest = rest $$0 "\n" } \
			END { printf "%s%s%s", first, rest, short }' \
		| $(PARALLEL)
	dvc stage list --name-only | grep '^evaluate' | $(PARALLEL)
	dvc repro report

# The studies of params.yaml's `studies:` (studies/dvc.yaml: socnav-wm sweep on local Ray, one
# task per core), after the world model they train on, then `study_claims`: the paper's claims
# with the studies' evidence (reports/studies/claims.md).
study: $(STAMP)
	PATH="$(CURDIR)/$(BIN):$$PATH" dvc repro studies/dvc.yaml

# Every non-learning method on the test scenarios of every preset of configs/scenarios/
# (scenarios/dvc.yaml), then their table (reports/scenarios.md, docs/scenarios.md).
scenarios: $(STAMP)
	PATH="$(CURDIR)/$(BIN):$$PATH" dvc repro scenarios/dvc.yaml

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest -n 2 -q --durations=15

bench: $(STAMP)
	$(BIN)/socnav-wm bench env

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
