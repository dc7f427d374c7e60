# wpbench: every target first runs scripts/setup.sh, which is idempotent
# (a few seconds when everything is in place), so any target works on a fresh
# Debian 12 machine. Override variables on the command line, e.g.
#   make run POLICY=gt TASK=open-door EPISODES=10
#   make test PYTEST_ARGS="-k records"

VENV        ?= .venv
PYTHON      := $(VENV)/bin/python
WPBENCH     := $(VENV)/bin/wpbench
POLICY      ?= wp
TASK        ?= open-then-place
SPLIT       ?= val
EPISODES    ?= 20
# The executor `wpbench run` uses when none is named (wpbench.names.DEFAULT_EXECUTOR), read
# when a recipe needs it, after setup has made the venv.
EXECUTOR    ?= $(shell $(PYTHON) -c 'from wpbench.names import DEFAULT_EXECUTOR; print(DEFAULT_EXECUTOR)')
RUN_ARGS    ?=
# `make run` writes to its own folder (git-ignored), so it really runs its episodes even
# though the published runs under results/runs/ are committed; rerunning it resumes. The
# folder is named after the executor (a run is never resumed with another one) and after
# the shipped weights: after new weights arrive (git pull), the
# next `make run` starts a new run instead of refusing to resume the old one, which stays
# (`=`, not `:=`: the weights are hashed only by the targets that use RUN_OUT).
WEIGHTS_ID   = $(shell cat policies/weights/best.json policies/weights/*/model.pt 2>/dev/null | sha256sum | cut -c1-8)
RUN_OUT     ?= runs/$(POLICY)__$(TASK)__$(SPLIT)__$(EXECUTOR)__weights-$(WEIGHTS_ID)
RESULTS     ?= results
PYTEST_ARGS ?=

export WPBENCH_VENV := $(abspath $(VENV))

.PHONY: help setup run test bench leaderboard

help:
	@echo "make run          set up, then evaluate POLICY=$(POLICY) on TASK=$(TASK) (SPLIT=$(SPLIT), EPISODES=$(EPISODES)) into $(RUN_OUT)"
	@echo "make test         set up, then run the test suite"
	@echo "make bench        set up, then print the speed benchmarks"
	@echo "make leaderboard  rebuild $(RESULTS)/leaderboard.{md,csv,png} from every summary.json"
	@echo "make setup        system packages + $(VENV) (idempotent)"

setup:
	@bash scripts/setup.sh

run: setup
	$(WPBENCH) run --policy $(POLICY) --task $(TASK) --split $(SPLIT) --episodes $(EPISODES) \
		--executor $(EXECUTOR) --out $(RUN_OUT) --resume $(RUN_ARGS)

# pytest exits with 5 when it collected no tests: that is a failure here too.
test: setup
	@status=0; $(PYTHON) -m pytest -q -p no:cacheprovider $(PYTEST_ARGS) || status=$$?; \
	if [ $$status -eq 5 ]; then echo "make test: pytest collected no tests" >&2; exit 1; fi; \
	exit $$status

bench: setup
	$(WPBENCH) bench svd
	$(WPBENCH) bench models

leaderboard: setup
	$(WPBENCH) leaderboard --results $(RESULTS)
