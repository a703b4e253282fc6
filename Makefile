# The two README commands. Everything else is `pipeline --help` and dvc.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# dvc runs stage commands (`pipeline ...`) through the shell: put the venv first on PATH
RUN    := PATH="$(CURDIR)/$(BIN):$$PATH"

.PHONY: demo test clean sync

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(RUN) dvc repro
	@echo
	@echo "Report:      reports/report.md  (figures in reports/figures/, numbers in reports/metrics.json)"
	@echo "Rerun view:  $(BIN)/rerun reports/recording.rrd"
	@echo "ROS 2 bags:  recordings/*/  (ros2 bag info recordings/paper-ctc, or open the .mcap in Foxglove)"

# the suite on $(TEST_WORKERS) pytest-xdist workers, a test module (its shared fixtures) or an
# xdist group (the Ray tests) to one worker (tests/conftest.py). TEST_WORKERS=0: one process
TEST_WORKERS ?= 2

test: $(STAMP)
	$(BIN)/ruff check pipeline tests benches
	$(BIN)/ruff format --check pipeline tests benches
	$(BIN)/mypy
	$(RUN) pytest -n $(TEST_WORKERS) --dist loadscope

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache

# Write the files generated from the code (dvc.yaml's deps, RECORD_CODE, the built-in
# controllers' facts, the DVC plot colours, docs/report.md's metric definitions);
# `make sync` after adding a module, a controller or a metric. The tests check they are current.
sync: $(STAMP)
	$(BIN)/python -m pipeline.devtools.sync
